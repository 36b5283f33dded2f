#version 450
// A colour that depends on the fragment position, so a read-back proves real rasterisation.
layout(location = 0) out vec4 color;
void main() {
    color = vec4(gl_FragCoord.x < 32.0 ? 1.0 : 0.0, 0.5, 0.25, 1.0);
}
