#version 450
// Diagonal stripes four pixels wide in the level's tint: detail fine enough that a fragment density
// map's coarse fragments turn it into visible steps in the periphery.
//
// Built twice (see build.sh): pattern.frag.spv as is, for render passes with a density map
// attachment, and overlay.frag.spv with -DOVERLAY, which also samples the eye's layer of the
// density map into the lower-left quarter of the eye (red = horizontal density, green = vertical)
// for devices that cannot render with it. heavy.frag.spv and heavy_overlay.frag.spv (-DHEAVY) add a
// loop of arithmetic per fragment, so that shading dominates the pass (`--heavy`: the fill-bound
// scene a GPU timing of coarse shading needs).

layout(location = 0) in vec2 uv;
layout(location = 0) out vec4 colour;
layout(push_constant) uniform Frame {
    vec4 tint;
} frame;
#ifdef OVERLAY
layout(set = 0, binding = 0) uniform sampler2D density;
#endif

void main() {
    float stripe = step(4.0, mod(gl_FragCoord.x + gl_FragCoord.y, 8.0));
    colour = vec4(frame.tint.rgb * (0.5 + 0.5 * stripe), 1.0);
#ifdef HEAVY
    vec2 p = gl_FragCoord.xy * 0.013;
    float acc = 0.0;
    for (int i = 0; i < 512; ++i) {
        p = vec2(sin(p.x * 1.31 + p.y), cos(p.y * 1.73 - p.x));
        acc += p.x * p.y;
    }
    colour.rgb *= 0.8 + 0.2 * fract(acc);
#endif
#ifdef OVERLAY
    if (uv.x < 0.5 && uv.y >= 0.5) {
        colour = vec4(texture(density, vec2(uv.x * 2.0, uv.y * 2.0 - 1.0)).rg, 0.0, 1.0);
    }
#endif
}
