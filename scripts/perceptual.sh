#!/bin/sh
# What each foveation level costs the eye, measured with a published perceptual metric (NVIDIA's
# FLIP) per eccentricity band, and how blocky the periphery is, from frames read back.
#
# The example (examples/foveated_vulkan) draws its room scene (--scene room: textured wall and
# floor, hard edges, small text at several eccentricities, a slow pan) on the simulated headset
# through the system's Khronos OpenXR loader, fovea's OpenXR layer and fovea's Vulkan layer, over
# the shading-rate double (crates/vkdouble: lavapipe made to look like an NVIDIA GPU with
# shading-rate attachments, which leaves each pass's colour as such a GPU shades it). Each level
# (none, low, medium, high) runs alone for the same frames, so the last frame of each is the same
# image at a different level; level NONE is the full-rate reference. It runs for each headset
# (Quest 3 and Valve Index geometry) with fixed foveation and with an eye-tracked profile whose
# fovea follows a scripted gaze (15° right, 8° up), and scripts/perceptual.py writes the table.
# Each level below NONE runs twice: its coarse blocks as shaded (FOVEA_SUBSAMPLED=off) and
# reconstructed (FOVEA_SUBSAMPLED=on, docs/settings.md), for the table's "reconstructed" rows; a
# fovea without reconstruction ignores the setting, and the table says so.
#
# Usage: scripts/perceptual.sh [OUT_DIR]   (default: target/perceptual)
# Variables: HEADSETS (default "quest3 index"), FRAMES per run (default 3; 12 with the gaze, so
# the eye-tracked fovea has settled), RECONSTRUCT=off (skip the reconstructed runs), NO_BUILD=1
# (use what REL holds; REL defaults to target/release), DEVICE=gpu (render on the machine's own
# GPU through fovea's Vulkan layer instead of lavapipe and the double: scripts/gpu-proof.sh),
# FRAMES_ONLY=1 (write the frames and the model's figures, not the table: for a machine without
# the metric's environment; run scripts/perceptual.py on OUT_DIR elsewhere).
# FOVVIDEOVDP=1 also rates each frame with FovVideoVDP (scripts/fovvideovdp.py: one figure in JOD
# for the whole frame as the eye that fixates the gaze sees it; pyfvvdp pulls in torch, about 4 GB,
# and takes about 20 s a frame on two CPU cores).
# The metrics' own environment (flip-evaluator, numpy, Pillow; pyfvvdp) is a virtual environment
# in OUT_DIR/venv, made on first use from PyPI. Nothing of it is shipped or linked.
set -eu
cd "$(dirname "$0")/.."
ROOT=$(pwd)
OUT=${1:-target/perceptual}
HEADSETS=${HEADSETS:-quest3 index}
FRAMES=${FRAMES:-3}
RECONSTRUCT=${RECONSTRUCT:-on}
DEVICE=${DEVICE:-double}
REL=${REL:-$ROOT/target/release}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)

if [ "${FRAMES_ONLY:-0}" != 1 ] && [ ! -x "$OUT/venv/bin/python" ]; then
    python3 -m venv "$OUT/venv"
    "$OUT/venv/bin/pip" install --quiet flip-evaluator==1.7 numpy pillow
fi
if [ "${FOVVIDEOVDP:-0}" = 1 ] && [ "${FRAMES_ONLY:-0}" != 1 ] \
    && ! "$OUT/venv/bin/python" -c 'import pyfvvdp' 2>/dev/null; then
    "$OUT/venv/bin/pip" install --quiet pyfvvdp==1.2.2
fi
if [ "${NO_BUILD:-0}" != 1 ]; then
    cargo build --release -p fovea -p fovea-sim -p fovea-cli -p fovea-vkdouble --lib --bins \
        --example foveated_vulkan
fi

# The Vulkan side: lavapipe and the double below fovea's Vulkan layer, or the machine's GPU.
# (Paths with spaces are not supported: VK_ENV is split into words.)
if [ "$DEVICE" = gpu ]; then
    VK_ENV="VK_ADD_LAYER_PATH=$ROOT/manifest/vulkan${VK_ADD_LAYER_PATH:+:$VK_ADD_LAYER_PATH}"
    DOUBLE=""
else
    LVP=$(find /usr/share/vulkan/icd.d -name 'lvp_icd*.json' 2>/dev/null | sort | head -n 1)
    [ -n "$LVP" ] || { echo "lavapipe (mesa-vulkan-drivers) is not installed" >&2; exit 1; }
    VK_ENV="VK_DRIVER_FILES=$LVP VK_ADD_LAYER_PATH=$ROOT/manifest/vulkan:$OUT/vk"
    DOUBLE="--vk-layer VK_LAYER_FOVEA_shading_rate_double"
fi
# The double's manifest, as fovea_vkdouble::manifest_json writes it.
mkdir -p "$OUT/vk"
cat >"$OUT/vk/VkLayer_fovea_shading_rate_double.json" <<EOF
{"file_format_version":"1.1.2","layer":{"name":"VK_LAYER_FOVEA_shading_rate_double",
"type":"GLOBAL","library_path":"$REL/libfovea_vkdouble.so","api_version":"1.4.359",
"implementation_version":"1","description":"fovea test double",
"device_extensions":[{"name":"VK_KHR_fragment_shading_rate","spec_version":"2",
"entrypoints":["vkCmdSetFragmentShadingRateKHR"]},{"name":"VK_EXT_load_store_op_none","spec_version":"1"}]}}
EOF
RUNTIME=$OUT/fovea_sim_runtime.json
printf '{"file_format_version":"1.0.0","runtime":{"name":"fovea simulated headset","library_path":"%s"}}\n' \
    "$REL/libfovea_sim.so" >"$RUNTIME"

rm -rf "$OUT/frames"
mkdir -p "$OUT/frames" "$OUT/model"
for headset in $HEADSETS; do
    "$REL/fovea" report --headset "$headset" --json >"$OUT/model/$headset.json"
    for gaze in fixed gaze; do
        for run in none low low-smooth medium medium-smooth high high-smooth; do
            level=${run%-smooth}
            subsampled=off
            if [ "$run" != "$level" ]; then
                [ "$RECONSTRUCT" = on ] || continue
                subsampled=on
            fi
            dir=$OUT/frames/$headset-$gaze-$run
            mkdir -p "$dir"
            if [ "$gaze" = gaze ]; then
                set -- --eye-tracked --frames "$((FRAMES + 9))"
                export FOVEA_SIM_EYE_GAZE=on FOVEA_SIM_GAZE="fix 15,8 for 1000s"
            else
                set -- --frames "$FRAMES"
                unset FOVEA_SIM_EYE_GAZE FOVEA_SIM_GAZE
            fi
            # shellcheck disable=SC2086 # $VK_ENV: assignments for env; $DOUBLE: empty or an option.
            env $VK_ENV \
                XR_RUNTIME_JSON="$RUNTIME" XR_API_LAYER_PATH="$ROOT/manifest" \
                XR_ENABLE_API_LAYERS=XR_APILAYER_FOVEA_foveation DISABLE_FOVEA_VK_LAYER=1 \
                FOVEA_SIM_HEADSET="$headset" FOVEA_SUBSAMPLED="$subsampled" \
                "$REL/examples/foveated_vulkan" --scene room --levels "$level" "$@" \
                --frames-per-level 1000 $DOUBLE \
                --dump "$dir" >"$dir/run.txt" 2>"$dir/run.log" || {
                echo "the example failed ($headset, $gaze, $run): see $dir/run.log" >&2
                exit 1
            }
            echo "$headset $gaze $run: $(grep -c . "$dir/run.txt") lines, $(find "$dir" -name '*left.png' | grep -c .) left frames"
        done
    done
done
if [ "${FRAMES_ONLY:-0}" = 1 ]; then
    echo "frames: $OUT/frames; the table: scripts/perceptual.py $OUT/frames $OUT/model $OUT"
    exit 0
fi
"$OUT/venv/bin/python" scripts/perceptual.py "$OUT/frames" "$OUT/model" "$OUT"
echo "table: $OUT/table.md"
if [ "${FOVVIDEOVDP:-0}" = 1 ]; then
    (cd scripts && "$OUT/venv/bin/python" fovvideovdp.py "$OUT/frames" "$OUT")
    echo "FovVideoVDP: $OUT/fovvideovdp.md"
fi
