#!/bin/sh
# Rebuilds the checked-in SPIR-V from the GLSL next to it (Debian: glslang-tools). The layer's tests
# `vk::own::convert_shader::tests::shader_matches_its_source` and
# `vk::own::recon_shader::tests::shader_matches_its_source` run the same commands and compare the bytes.
set -e
cd "$(dirname "$0")"
glslangValidator -V --target-env vulkan1.1 -o convert.comp.spv convert.comp
glslangValidator -V --target-env vulkan1.1 -o reconstruct.comp.spv reconstruct.comp
