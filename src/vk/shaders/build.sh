#!/bin/sh
# Rebuilds the checked-in SPIR-V from the GLSL next to it (Debian: glslang-tools). The layer's test
# `vk::own::convert_shader::tests::shader_matches_its_source` runs the same command and compares the bytes.
set -e
cd "$(dirname "$0")"
glslangValidator -V --target-env vulkan1.1 -o convert.comp.spv convert.comp
