#version 450
// The application's own compute work in tests/suite/vk_convert.rs: writes its push constant
// through its descriptor set, so a read-back shows which bindings a dispatch used.
layout(local_size_x = 1) in;
layout(set = 0, binding = 0, std430) buffer Out { uint value[]; };
layout(push_constant) uniform Push { uint word; uint index; } pc;
void main() {
    value[pc.index] = pc.word;
}
