#version 450
// A room like the ones VR apps draw (`--scene room`), procedural so the example needs no assets:
// a brick wall and a receding checkered floor, both textured down to the pixel (so that a block
// of pixels is uniform only where coarse fragments made it so), high-contrast edges (mortar,
// tiles, thin dark poles), and panels of small text (glyphs of 3×5 cells, about 7×12 pixels at
// Quest 3's resolution) at several distances from the view's centre. The camera pans slowly to
// the right (push constant `w`: the frame number), for temporal artefacts. Everything is laid out
// in the view's uv, so each headset sees the same angles. The level's tint is not used: every
// level draws the same image at full rate, so a level's frame compares pixel for pixel with level
// NONE's (scripts/perceptual.sh).
//
// Built twice (see build.sh): scene.frag.spv, and scene_overlay.frag.spv with -DOVERLAY, which
// also samples the eye's layer of the density map into the lower-left quarter of the eye, as
// pattern.frag's overlay does.

layout(location = 0) in vec2 uv;
layout(location = 0) out vec4 colour;
layout(push_constant) uniform Frame {
    vec4 tint;
} frame;
#ifdef OVERLAY
layout(set = 0, binding = 0) uniform sampler2D density;
#endif

// uv per frame the camera pans: 1% of the view a second at 90 Hz.
const float PAN = 0.01 / 90.0;
// A glyph cell's side in uv: 1/900 of the view.
const float CELL = 1.0 / 900.0;
// Hex digits in 3×5 cells, rows top to bottom, the top row in bits 14..12.
const uint FONT[16] = uint[16](0x7B6Fu, 0x2C97u, 0x73E7u, 0x73CFu, 0x5BC9u, 0x79CFu, 0x79EFu,
    0x7249u, 0x7BEFu, 0x7BCFu, 0x2BEDu, 0x6BAEu, 0x3923u, 0x6B6Eu, 0x79A7u, 0x79A4u);
// Text panels' centres (uv, before the pan): along the horizon and above and below the centre.
const vec2 PANELS[9] = vec2[9](vec2(0.5, 0.42), vec2(0.62, 0.42), vec2(0.75, 0.42),
    vec2(0.88, 0.42), vec2(0.38, 0.42), vec2(0.25, 0.42), vec2(0.12, 0.42), vec2(0.5, 0.18),
    vec2(0.5, 0.72));
const vec2 PANEL_HALF = vec2(0.05, 0.03);

uint hash(uvec2 p) {
    uint h = p.x * 374761393u + p.y * 668265263u;
    h = (h ^ (h >> 13)) * 1274126177u;
    return h ^ (h >> 16);
}

float rand(vec2 cell) {
    return float(hash(uvec2(ivec2(floor(cell)) + 4096)) & 0xFFFFu) / 65535.0;
}

// Value noise with a smooth step between lattice points.
float noise(vec2 p) {
    vec2 i = floor(p);
    vec2 f = fract(p);
    f = f * f * (3.0 - 2.0 * f);
    return mix(mix(rand(i), rand(i + vec2(1, 0)), f.x), mix(rand(i + vec2(0, 1)), rand(i + 1.0), f.x),
        f.y);
}

vec3 wall(vec2 p) {
    vec2 brick = vec2(0.06, 0.025);
    float row = floor(p.y / brick.y);
    vec2 q = vec2(p.x / brick.x + 0.5 * mod(row, 2.0), p.y / brick.y);
    vec2 f = fract(q);
    float mortar = 0.0025;
    bool joint = f.x * brick.x < mortar || f.y * brick.y < mortar;
    float shade = 0.75 + 0.25 * rand(floor(q) + 17.0);
    float grain = 0.8 + 0.2 * noise(p * 900.0) + 0.1 * (noise(p * 120.0) - 0.5);
    vec3 c = joint ? vec3(0.08) : vec3(0.55, 0.22, 0.14) * shade * grain;
    return c;
}

vec3 floor_(vec2 p) {
    // Perspective: the horizon at v = 0.5, tiles shrink towards it.
    float depth = 0.12 / max(p.y - 0.5, 0.002);
    vec2 world = vec2((p.x - 0.5) * depth * 2.0, depth);
    vec2 tile = floor(world / 0.35);
    bool dark = mod(tile.x + tile.y, 2.0) > 0.5;
    float grain = 0.85 + 0.15 * noise(p * 900.0);
    return (dark ? vec3(0.06, 0.06, 0.07) : vec3(0.85, 0.83, 0.78)) * grain;
}

// A panel of text: white with black hex digits in lines; `d` is uv from its centre.
vec3 panel(vec2 d, float seed) {
    vec2 cell = floor((d + PANEL_HALF) / CELL);
    vec2 glyph = floor(cell / vec2(4.0, 7.0));
    vec2 inside = cell - glyph * vec2(4.0, 7.0);
    vec3 paper = vec3(0.92, 0.92, 0.88) * (0.95 + 0.05 * noise((d + seed) * 900.0));
    if (inside.x > 2.0 || inside.y > 4.0) {
        return paper;
    }
    uint h = hash(uvec2(glyph + seed * 97.0 + 512.0));
    if (h % 6u == 0u) {
        return paper;
    }
    uint bit = 14u - uint(inside.y) * 3u - uint(inside.x);
    bool ink = ((FONT[h % 16u] >> bit) & 1u) == 1u;
    return ink ? vec3(0.03) : paper;
}

void main() {
    vec2 p = uv + vec2(frame.tint.w * PAN, 0.0);
    vec3 c = p.y < 0.5 ? wall(p) : floor_(p);
    // Thin dark poles: one-pixel-scale vertical edges.
    float pole = fract(p.x / 0.17);
    if (pole < 0.003 && p.y < 0.8) {
        c = vec3(0.02);
    }
    for (int i = 0; i < 9; ++i) {
        vec2 d = p - PANELS[i];
        if (abs(d.x) < PANEL_HALF.x && abs(d.y) < PANEL_HALF.y) {
            c = panel(d, float(i));
        } else if (abs(d.x) < PANEL_HALF.x + 0.003 && abs(d.y) < PANEL_HALF.y + 0.003) {
            c = vec3(0.01);
        }
    }
    colour = vec4(c, 1.0);
#ifdef OVERLAY
    if (uv.x < 0.5 && uv.y >= 0.5) {
        colour = vec4(texture(density, vec2(uv.x * 2.0, uv.y * 2.0 - 1.0)).rg, 0.0, 1.0);
    }
#endif
}
