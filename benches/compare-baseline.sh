#!/usr/bin/env bash
# Compares this tree's per-frame cost with a baseline commit's, side by side in one bench run.
#
#   benches/compare-baseline.sh [COMMIT] [criterion args...]
#
# COMMIT defaults to 15a7269 (the tree before the per-frame work). The script exports COMMIT's tree
# (git archive: no worktree is added) to a temporary directory, builds its layer with
# `cargo build --release -p fovea` into its own target directory, target/fovea-baseline (kept, so a
# second run is quick; not this workspace's target/release, where the two libfovea.so would overwrite
# each other), copies the library to target/libfovea-base.so (never committed: target/ is ignored),
# then runs
#
#   FOVEA_BENCH_BASELINE=target/libfovea-base.so cargo bench --bench frame_loop -- \
#       --warm-up-time 1 --measurement-time 3
#
# which times three loops in the same process: `bare` (no layer), `baseline` (COMMIT's layer) and
# `fovea` (this tree's layer). The last two lines printed are the interleaved summary: added ns per
# frame and the ratio against the bare loop for each layer, heap allocations per frame, and the new
# added cost as a fraction of the baseline's. Run it three times for three figures (after the first,
# `cargo build --release -p fovea && FOVEA_BENCH_BASELINE=target/libfovea-base.so cargo bench --bench
# frame_loop -- ...` will do). cargo bench does not build the layer's cdylib, so this tree's
# libfovea.so is built first.
#
# FOVEA_BENCH_BASELINE may also be set by hand to any built libfovea.so.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
commit=${1:-15a7269}
shift || true
args=("$@")
[ ${#args[@]} -eq 0 ] && args=(--warm-up-time 1 --measurement-time 3)
target=${CARGO_TARGET_DIR:-$root/target}
src=$(mktemp -d /tmp/fovea-baseline.XXXXXX)
trap 'rm -rf "$src"' EXIT
git -C "$root" archive "$commit" | tar -x -C "$src"
(cd "$src" && CARGO_TARGET_DIR="$target/fovea-baseline" cargo build --release -p fovea)
cp "$target/fovea-baseline/release/libfovea.so" "$target/libfovea-base.so"
cd "$root"
cargo build --release -p fovea
FOVEA_BENCH_BASELINE="$target/libfovea-base.so" cargo bench --bench frame_loop -- "${args[@]}"
