#!/bin/sh
# GPU proof of fovea's Vulkan layer (VK_LAYER_FOVEA_fragment_density_map) on a machine with a real
# Vulkan GPU and no headset: the example app renders on the simulated runtime (crates/sim) through
# the system's Khronos OpenXR loader, as `fovea demo` does.
#
#   1. what the driver offers (fovea doctor's per-GPU line; vulkaninfo --summary where installed);
#   2. the example's fill-bound scene (--heavy) at each level, with and without the Vulkan layer,
#      eye passes timed with GPU timestamps: a table of GPU ms per eye pass per level, as a ratio
#      to level NONE, beside the shaded fraction fovea's model predicts (fovea report --json);
#   3. frames read back from the GPU as PNGs (--dump), where coarse shading shows in the periphery,
#      and the fragment size each density-map texel was shaded at, read from those pixels, against
#      what the map allows (--check-rates);
#   4. injection (docs/injection.md): the same fill-bound scene from an app that never asks for
#      foveation (--no-fb: no XR_FB_foveation, plain passes), with injection off and at each
#      injected level (FOVEA_INJECT=1 FOVEA_INJECT_LEVEL=low|medium|high), eye passes timed the
#      same way, and frames read back with offscreen passes (which must stay at full rate), in the
#      array and the double-wide layout.
#
# Usage: scripts/gpu-proof.sh [OUT_DIR]   (default: target/gpu-proof)
# Variables: HEADSET (default quest3), FRAMES per run (default 120), FOVEA_SIM_VK_DEVICE (pick a
# GPU by name), NO_BUILD=1 (use what target/release holds), REL (the build folder, default
# target/release).
# Nothing here needs a GPU to run (on lavapipe it says there is nothing to measure), and no test
# or CI job depends on one.
set -eu
cd "$(dirname "$0")/.."
ROOT=$(pwd)
OUT=${1:-target/gpu-proof}
HEADSET=${HEADSET:-quest3}
FRAMES=${FRAMES:-120}
# Sections 3 and 4 read back 2 frames; the timed runs of section 4 take as many as section 2's.
TIMED_FRAMES=$FRAMES
REL=${REL:-$ROOT/target/release}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)

if [ "${NO_BUILD:-0}" != 1 ]; then
    cargo build --release -p fovea -p fovea-sim -p fovea-cli --lib --bins --example foveated_vulkan
fi

echo "== 1. What the driver offers"
# doctor asks the driver with fovea's layer kept out.
"$REL/fovea" doctor 2>&1 | sed -n '/^GPUs/,/^[^ ]/p' | grep -v '^problem' || true
if command -v vulkaninfo >/dev/null 2>&1; then
    vulkaninfo --summary 2>/dev/null | sed -n '/^Devices:/,$p' || true
    vulkaninfo 2>/dev/null | grep -E 'fragmentDensityMap|attachmentFragmentShadingRate|ShadingRateAttachmentTexelSize|layeredShadingRateAttachments|maxFragmentSize ' | sort -u || true
fi

# The OpenXR side: fovea's explicit layer manifest (in-tree) and the simulated runtime.
RUNTIME=$OUT/fovea_sim_runtime.json
printf '{"file_format_version":"1.0.0","runtime":{"name":"fovea simulated headset","library_path":"%s"}}\n' \
    "$REL/libfovea_sim.so" >"$RUNTIME"

# run WITH|WITHOUT LEVEL [example args]: the example's output on stdout, its log in OUT.
run() {
    mode=$1 level=$2
    shift 2
    if [ "$mode" = with ]; then
        vk="VK_ADD_LAYER_PATH=$ROOT/manifest/vulkan${VK_ADD_LAYER_PATH:+:$VK_ADD_LAYER_PATH}"
    else
        vk="VK_LOADER_LAYERS_DISABLE=VK_LAYER_FOVEA_fragment_density_map"
    fi
    # DISABLE_FOVEA_VK_LAYER keeps an installed implicit copy out either way.
    env "$vk" XR_RUNTIME_JSON="$RUNTIME" XR_API_LAYER_PATH="$ROOT/manifest" \
        XR_ENABLE_API_LAYERS=XR_APILAYER_FOVEA_foveation DISABLE_FOVEA_VK_LAYER=1 \
        FOVEA_SIM_HEADSET="$HEADSET" \
        "$REL/examples/foveated_vulkan" --heavy --levels "$level" \
        --frames "$FRAMES" --frames-per-level "$FRAMES" "$@" 2>"$OUT/$mode-$level.log"
}

echo
echo "== 2. Fill-bound eye passes on the simulated $HEADSET, $FRAMES frames per level"
"$REL/fovea" report --headset "$HEADSET" --json >"$OUT/model.json"
attached=no
for mode in without with; do
    for level in none low medium high; do
        run "$mode" "$level" >"$OUT/$mode-$level.txt" || {
            echo "the example failed ($mode, $level): see $OUT/$mode-$level.log" >&2
            exit 1
        }
        if [ "$mode" = with ] && grep -q 'attached to the render pass' "$OUT/$mode-$level.txt"; then
            attached=yes
        fi
    done
done
mean() { sed -n "s/.*eye-pass GPU ms level=$2 mean=\([0-9.]*\).*/\1/p" "$OUT/$1-$2.txt"; }
fraction() {
    tr '{' '\n' <"$OUT/model.json" | sed -n "s/.*\"level\":\"$1\",\"shaded_fraction\":\([0-9.]*\).*/\1/p"
}
if [ "$attached" = no ]; then
    echo "no shading-rate attachments: nothing to measure (the density maps went to the debug"
    echo "overlay; the timings below are the same scene without foveation)"
fi
printf '%-7s %9s %12s %8s %12s %8s\n' level model "without ms" ratio "with ms" ratio
n0=$(mean without none)
w0=$(mean with none)
for level in none low medium high; do
    n=$(mean without "$level")
    w=$(mean with "$level")
    awk -v l="$level" -v f="$(fraction "$level")" -v n="$n" -v n0="$n0" -v w="$w" -v w0="$w0" \
        'BEGIN { printf "%-7s %9.3f %12.4f %8.3f %12.4f %8.3f\n", l, f, n, (n0 > 0 ? n / n0 : 0), w, (w0 > 0 ? w / w0 : 0) }'
done
echo "(model: shaded fraction fovea's density model predicts; ratio: GPU time per eye pass over"
echo " level NONE's in the same mode; without = VK_LOADER_LAYERS_DISABLE keeps the Vulkan layer out)"

echo
echo "== 3. Frames read back from the GPU"
FRAMES_DIR=$OUT/frames
rm -rf "$FRAMES_DIR"
FRAMES=2
run with high --dump "$FRAMES_DIR" --check-rates >"$OUT/dump.txt" || {
    echo "the example failed or found texels shaded coarser than their map allows: see $OUT/dump.txt" >&2
    exit 1
}
grep -E 'PNGs|shaded sizes|rates not checked' "$OUT/dump.txt" || true
echo "fNNNNN_high_{left,right}.png: with shading-rate attachments, coarse blocks in the periphery;"
echo "the shaded sizes are read from those pixels, per density-map texel (--check-rates)"

FRAMES=$TIMED_FRAMES
echo
echo "== 4. Injection: the scene from an app without the FB API (--no-fb), $FRAMES frames per level"
# run_inject LEVEL [example args]: LEVEL is off or an injected level; fovea's Vulkan layer is in
# either way (injection needs it), so `off` differs from the others by FOVEA_INJECT alone.
run_inject() {
    level=$1
    shift
    if [ "$level" = off ]; then
        inject="FOVEA_INJECT=0"
    else
        inject="FOVEA_INJECT=1 FOVEA_INJECT_LEVEL=$level"
    fi
    # shellcheck disable=SC2086 # $inject is one or two assignments for env.
    env VK_ADD_LAYER_PATH="$ROOT/manifest/vulkan${VK_ADD_LAYER_PATH:+:$VK_ADD_LAYER_PATH}" \
        XR_RUNTIME_JSON="$RUNTIME" XR_API_LAYER_PATH="$ROOT/manifest" \
        XR_ENABLE_API_LAYERS=XR_APILAYER_FOVEA_foveation DISABLE_FOVEA_VK_LAYER=1 \
        FOVEA_SIM_HEADSET="$HEADSET" FOVEA_LOG="${FOVEA_LOG:-info}" $inject \
        "$REL/examples/foveated_vulkan" --no-fb --heavy --frames "$FRAMES" "$@" \
        2>"$OUT/inject-$level.log"
}
for level in off low medium high; do
    run_inject "$level" >"$OUT/inject-$level.txt" || {
        echo "the example failed (--no-fb, injection $level): see $OUT/inject-$level.log" >&2
        exit 1
    }
done
# The eye passes of a --no-fb run are all timed under the app's one level, NONE.
inject_mean() { sed -n 's/.*eye-pass GPU ms level=none mean=\([0-9.]*\).*/\1/p' "$OUT/inject-$1.txt"; }
# fovea's stats line counts injected eye passes per frame (`Inj=eye/all`); a build that does not
# inject prints none.
injected() { sed -n 's/.*Inj=\([0-9]*\/[0-9]*\).*/\1/p' "$OUT/inject-$1.log" | tail -n 1; }
case "$(injected high)" in
"" | 0/*)
    echo "no eye pass was injected at high (no shading-rate attachments on this device, or a build"
    echo "of fovea without injection): the timings below are the same scene without foveation"
    ;;
esac
printf '%-7s %9s %12s %8s %10s\n' level model "ms" ratio "Inj="
i0=$(inject_mean off)
for level in off low medium high; do
    f=1
    [ "$level" = off ] || f=$(fraction "$level")
    awk -v l="$level" -v f="$f" -v m="$(inject_mean "$level")" -v m0="$i0" -v inj="$(injected "$level")" \
        'BEGIN { printf "%-7s %9.3f %12.4f %8.3f %10s\n", l, f, m, (m0 > 0 ? m / m0 : 0), (inj == "" ? "-" : inj) }'
done
echo "(ratio: GPU time per eye pass over injection off's; Inj=: eye passes injected / passes begun"
echo " in the last frame, from fovea's stats line; '-' where this build of fovea logged none)"

INJECT_DIR=$OUT/inject-frames
rm -rf "$INJECT_DIR"
FRAMES=2
for layout in array double-wide; do
    extra=""
    [ "$layout" = array ] || extra="--double-wide"
    # shellcheck disable=SC2086 # $extra is empty or one option.
    run_inject high --offscreen $extra --dump "$INJECT_DIR/$layout" >"$OUT/inject-dump-$layout.txt"
    grep 'PNGs' "$OUT/inject-dump-$layout.txt" || true
done
echo "$INJECT_DIR/{array,double-wide}/fNNNNN_none_{left,right}.png: injected at high, coarse blocks in"
echo "the periphery of the eyes. The offscreen targets (256x256, 64x36) are not eye passes and render"
echo "at full rate; their blue stripes in each eye's upper-right corner are coarse only as far as the"
echo "eye pass that draws them there is"
