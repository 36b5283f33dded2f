#!/bin/sh
# Rebuilds the checked-in SPIR-V from the GLSL next to it (Debian: glslang-tools). The example's test
# `shaders_match_their_sources` runs the same commands and compares the bytes.
set -e
cd "$(dirname "$0")"
glslangValidator -V --target-env vulkan1.1 -o fullscreen.vert.spv fullscreen.vert
glslangValidator -V --target-env vulkan1.1 -o pattern.frag.spv pattern.frag
glslangValidator -V --target-env vulkan1.1 -DOVERLAY -o overlay.frag.spv pattern.frag
glslangValidator -V --target-env vulkan1.1 -DHEAVY -o heavy.frag.spv pattern.frag
glslangValidator -V --target-env vulkan1.1 -DHEAVY -DOVERLAY -o heavy_overlay.frag.spv pattern.frag
glslangValidator -V --target-env vulkan1.1 -o composite.frag.spv composite.frag
glslangValidator -V --target-env vulkan1.1 -o scene.frag.spv scene.frag
glslangValidator -V --target-env vulkan1.1 -DOVERLAY -o scene_overlay.frag.spv scene.frag
