#version 450
// Draws an offscreen target over the viewport (`--offscreen`): the "shadow map" into the tiny target,
// and the tiny target into a corner of each eye, so that neither offscreen pass is dead work.

layout(location = 0) in vec2 uv;
layout(location = 0) out vec4 colour;
layout(set = 0, binding = 0) uniform sampler2D source;

void main() {
    colour = vec4(texture(source, uv).rgb, 1.0);
}
