#version 450
// Density map (R8G8_UNORM, sampled) to shading-rate codes (R8_UINT), for density maps an
// application writes itself (src/vk/convert.rs, docs/vulkan-fdm-on-fsr.md#rate-encoding).
// Each invocation writes one 32-bit word of the output buffer: four consecutive codes, so no two
// invocations write the same word. The output is tightly packed R8 texels, layer after layer
// (one layer where `merged`), ready for vkCmdCopyBufferToImage into the shadow.
// Must give the same bytes as fovea_model::shading_rate::fill_codes; the table carries everything
// device-specific (the clamp to listed rates and maxFragmentSize).
#extension GL_EXT_samplerless_texture_functions : require

layout(local_size_x = 64) in;

layout(set = 0, binding = 0) uniform texture2DArray density;
layout(set = 0, binding = 1, std430) writeonly buffer Codes { uint words[]; };
// Density-map offsets (VK_EXT_fragment_density_map_offset), per density layer, in whole texels:
// written by the host when the pass's end is recorded, before the submit that runs this
// (src/vk/convert.rs). Layers from MAX_SHIFTS on are not shifted.
const uint MAX_SHIFTS = 16u;
layout(set = 0, binding = 2, std430) readonly buffer Shifts { ivec2 shifts[MAX_SHIFTS]; };

layout(push_constant) uniform Push {
    uint width;
    uint height;
    // Density layers read.
    uint layers;
    // Nonzero: one output layer holding per texel the finer rate of all density layers.
    uint merged;
    // table[w * 4 + h], w and h the wanted log2 fragment edges, as bytes of four words.
    uvec4 table;
} pc;

uint table_at(uint w, uint h) {
    uint i = w * 4u + h;
    return (pc.table[i >> 2u] >> ((i & 3u) * 8u)) & 0xffu;
}

// axis_size as a log2: byte 0 → 0 (1 pixel); otherwise the largest power of two ≤ min(4, 255 / byte).
uint axis_log2(uint b) {
    if (b == 0u || b >= 128u) {
        return 0u;
    }
    return b >= 64u ? 1u : 2u;
}

// The specification's lookup with an offset (x' = x - offset, clamped to the map), per layer.
uint code_of(uint x, uint y, uint layer) {
    ivec2 shift = layer < MAX_SHIFTS ? shifts[layer] : ivec2(0);
    ivec2 last = ivec2(int(pc.width) - 1, int(pc.height) - 1);
    ivec2 at = clamp(ivec2(int(x), int(y)) - shift, ivec2(0), last);
    vec2 d = texelFetch(density, ivec3(at, int(layer)), 0).rg;
    uvec2 b = uvec2(round(clamp(d, 0.0, 1.0) * 255.0));
    return table_at(axis_log2(b.x), axis_log2(b.y));
}

void main() {
    uint texels = pc.width * pc.height;
    uint total = pc.merged != 0u ? texels : texels * pc.layers;
    uint word = gl_GlobalInvocationID.x;
    if (word * 4u >= total) {
        return;
    }
    uint packed = 0u;
    for (uint k = 0u; k < 4u; ++k) {
        uint j = word * 4u + k;
        if (j >= total) {
            break;
        }
        uint t = j % texels;
        uint x = t % pc.width;
        uint y = t / pc.width;
        uint c;
        if (pc.merged != 0u) {
            // As fovea_model::shading_rate::finer, layer after layer.
            c = code_of(x, y, 0u);
            for (uint l = 1u; l < pc.layers; ++l) {
                uint n = code_of(x, y, l);
                c = table_at(min((c >> 2u) & 3u, (n >> 2u) & 3u), min(c & 3u, n & 3u));
            }
        } else {
            c = code_of(x, y, j / texels);
        }
        packed |= c << (k * 8u);
    }
    words[word] = packed;
}
