#version 450
// A colour that changes from pixel to pixel (a hash of the pixel's position): a block of pixels
// is uniform only where coarse fragments made it so (tests/suite/vk/reconstruction.rs).
layout(location = 0) out vec4 color;
void main() {
    uvec2 p = uvec2(gl_FragCoord.xy);
    uint h = p.x * 73856093u ^ p.y * 19349663u;
    h ^= h >> 13;
    h *= 0x5bd1e995u;
    h ^= h >> 15;
    color = vec4(float(h & 255u), float((h >> 8) & 255u), float((h >> 16) & 255u), 255.0) / 255.0;
}
