#version 450
// Reconstruction of coarse blocks (src/vk/reconstruct.rs, docs/reconstruction.md): what sampling a
// subsampled image with bilinear filtering gives. One invocation per texel of the render area and
// layer. `src` holds the colour attachment's raw texels (copied out of the application's image,
// tightly packed, layer after layer), `dst` gets the result (copied back), `rates` the
// shading-rate attachment's codes (R8, tightly packed, layer after layer).
// A texel shaded 1x1 gets its raw bits back: bit-identical. A texel of a w x h fragment gets the
// bilinear blend of the centres of the nearest blocks of the w x h grid (aligned to multiples of
// w x h in framebuffer coordinates), each taking the colour at its centre (whatever rate shaded
// it), clamped to the render area; decoded and re-encoded per format kind, sRGB in linear space.

layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 0, std430) readonly buffer Src { uint src[]; };
layout(set = 0, binding = 1, std430) writeonly buffer Dst { uint dst[]; };
layout(set = 0, binding = 2, std430) readonly buffer Rates { uint rates[]; };

layout(push_constant) uniform Push {
    // The render area: extent and offset in framebuffer coordinates.
    uint width;
    uint height;
    uint origin_x;
    uint origin_y;
    // The shading-rate image's extent in texels, and its texel in pixels.
    uint rate_width;
    uint rate_height;
    uint texel_width;
    uint texel_height;
    // 1 UNORM8, 2 SRGB8 (alpha linear), 3 10:10:10:2 UNORM, 4 RGBA16 SFLOAT, 5 RGBA16 UNORM.
    uint kind;
    // 32-bit words per texel (1 or 2).
    uint words;
    // Rate layers: 1 (one layer for every view) or one per colour layer.
    uint rate_layers;
    // Code c -> (log2 w << 2 | log2 h) of the fragment the device really shades, nibble c % 8 of
    // word c / 8.
    uint table0;
    uint table1;
} pc;

uint fetch(uint layer, uint x, uint y, uint k) {
    return src[((layer * pc.height + y) * pc.width + x) * pc.words + k];
}

float to_linear(float c) {
    return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
}

float to_srgb(float c) {
    return c <= 0.0031308 ? c * 12.92 : 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

vec4 decode(uint layer, ivec2 p) {
    uint x = uint(clamp(p.x, 0, int(pc.width) - 1));
    uint y = uint(clamp(p.y, 0, int(pc.height) - 1));
    uint w0 = fetch(layer, x, y, 0u);
    if (pc.kind == 1u) {
        return unpackUnorm4x8(w0);
    }
    if (pc.kind == 2u) {
        vec4 c = unpackUnorm4x8(w0);
        return vec4(to_linear(c.r), to_linear(c.g), to_linear(c.b), c.a);
    }
    if (pc.kind == 3u) {
        return vec4(float(w0 & 1023u), float((w0 >> 10) & 1023u), float((w0 >> 20) & 1023u),
                    float(w0 >> 30)) / vec4(1023.0, 1023.0, 1023.0, 3.0);
    }
    uint w1 = fetch(layer, x, y, 1u);
    if (pc.kind == 4u) {
        return vec4(unpackHalf2x16(w0), unpackHalf2x16(w1));
    }
    return vec4(unpackUnorm2x16(w0), unpackUnorm2x16(w1));
}

void encode(uint at, vec4 c) {
    if (pc.kind == 1u) {
        dst[at] = packUnorm4x8(c);
    } else if (pc.kind == 2u) {
        vec3 s = clamp(c.rgb, 0.0, 1.0);
        dst[at] = packUnorm4x8(vec4(to_srgb(s.r), to_srgb(s.g), to_srgb(s.b), c.a));
    } else if (pc.kind == 3u) {
        uvec4 q = uvec4(round(clamp(c, 0.0, 1.0) * vec4(1023.0, 1023.0, 1023.0, 3.0)));
        dst[at] = q.r | (q.g << 10) | (q.b << 20) | (q.a << 30);
    } else if (pc.kind == 4u) {
        dst[at] = packHalf2x16(c.rg);
        dst[at + 1u] = packHalf2x16(c.ba);
    } else {
        dst[at] = packUnorm2x16(c.rg);
        dst[at + 1u] = packUnorm2x16(c.ba);
    }
}

void main() {
    uvec3 id = gl_GlobalInvocationID;
    if (id.x >= pc.width || id.y >= pc.height) {
        return;
    }
    uint layer = id.z;
    uint fx = id.x + pc.origin_x;
    uint fy = id.y + pc.origin_y;
    uint rl = pc.rate_layers == 1u ? 0u : layer;
    uint tx = min(fx / pc.texel_width, pc.rate_width - 1u);
    uint ty = min(fy / pc.texel_height, pc.rate_height - 1u);
    uint i = (rl * pc.rate_height + ty) * pc.rate_width + tx;
    uint code = (rates[i >> 2] >> ((i & 3u) * 8u)) & 15u;
    uint t = code < 8u ? pc.table0 : pc.table1;
    uint size = (t >> ((code & 7u) * 4u)) & 15u;
    int bw = 1 << int(size >> 2);
    int bh = 1 << int(size & 3u);
    uint at = ((layer * pc.height + id.y) * pc.width + id.x) * pc.words;
    if (bw == 1 && bh == 1) {
        for (uint k = 0u; k < pc.words; k++) {
            dst[at + k] = src[at + k];
        }
        return;
    }
    // The block grid's centres around this texel's centre, in framebuffer coordinates.
    vec2 g = (vec2(float(fx), float(fy)) + 0.5 - 0.5 * vec2(bw, bh)) / vec2(bw, bh);
    vec2 g0 = floor(g);
    vec2 f = g - g0;
    ivec2 b0 = ivec2(g0);
    ivec2 size2 = ivec2(bw, bh);
    ivec2 origin = ivec2(int(pc.origin_x), int(pc.origin_y));
    ivec2 c00 = b0 * size2 + size2 / 2 - origin;
    ivec2 c11 = (b0 + 1) * size2 + size2 / 2 - origin;
    vec4 a = decode(layer, c00);
    vec4 b = decode(layer, ivec2(c11.x, c00.y));
    vec4 c = decode(layer, ivec2(c00.x, c11.y));
    vec4 d = decode(layer, c11);
    encode(at, mix(mix(a, b, f.x), mix(c, d, f.x), f.y));
}
