#version 450
// A colour that differs at every pixel, so coarse fragments (one shaded value over a block of
// pixels) are visible in a read-back.
layout(location = 0) out vec4 color;
void main() {
    color = vec4(gl_FragCoord.x / 64.0, gl_FragCoord.y / 64.0, 0.25, 1.0);
}
