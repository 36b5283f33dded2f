#version 450
// The application's compute path in tests/suite/vk_app_written_maps.rs: writes a density map with
// imageStore, as the Khronos fragment-density-map sample's compute path does. Each texel gets the
// bytes `app_written_maps::compute_bytes` gives it for the frame the push constant names.
layout(local_size_x = 1, local_size_y = 1) in;
layout(set = 0, binding = 0, rg8) uniform writeonly image2D map;
layout(push_constant) uniform Push { uint frame; } pc;
const uint LEVELS[5] = uint[5](0u, 30u, 100u, 160u, 255u);
void main() {
    uvec2 p = gl_GlobalInvocationID.xy;
    uint r = LEVELS[(p.x * 3u + p.y + pc.frame) % 5u];
    uint g = LEVELS[(p.x + p.y * 2u + pc.frame * 3u) % 5u];
    imageStore(map, ivec2(p), vec4(float(r), float(g), 0.0, 0.0) / 255.0);
}
