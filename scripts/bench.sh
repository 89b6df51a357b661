#!/usr/bin/env bash
# The standard measurements of geo (protocol: 128x416, batch 4 training steps, median of
# 5 after 2 warm-ups; inference at batch 1 and 4; FR on and off; loader on a small geo_synth
# world), written as a markdown table for the README and as JSON.
#   scripts/bench.sh [cpu|cuda] [more geo_bench options, e.g. --threads 2]
#   GEO_BUILD_DIR   build folder (default: build)
#   GEO_BENCH_OUT   where the results go (default: <build>/bench): <device>.md, <device>.json
# Takes about 10 minutes on 2 CPU cores. Close other work first: the timings are medians, but a
# busy machine still moves them.
set -euo pipefail
cd "$(dirname "$0")/.."
DEVICE="${1:-cpu}"
[ $# -gt 0 ] && shift
BUILD_DIR="${GEO_BUILD_DIR:-build}"
OUT="${GEO_BENCH_OUT:-$BUILD_DIR/bench}"
[ -x "$BUILD_DIR/apps/geo_bench" ] || scripts/setup.sh
mkdir -p "$OUT"

LOADER=()
if [ -x "$BUILD_DIR/apps/geo_synth" ]; then  # the OpenCV build: time the loader on KITTI-sized PNGs
  WORLD="$OUT/world"
  [ -d "$WORLD/raw" ] || "$BUILD_DIR/apps/geo_synth" --preset kitti --drives 1 --test-drives 1 --frames 20 \
    --flow-pairs 0 --odometry-frames 5 --out "$WORLD" >/dev/null
  LOADER=(--data-root "$WORLD/raw")
fi

"$BUILD_DIR/apps/geo_bench" --device "$DEVICE" --fr both --batch 1,4 --train-warmup 2 --train-iters 5 \
  --warmup 10 --iters 5 "${LOADER[@]}" --json "$OUT/$DEVICE.json" --markdown "$OUT/$DEVICE.md" "$@"
echo
cat "$OUT/$DEVICE.md"
echo "geo bench: wrote $OUT/$DEVICE.md and $OUT/$DEVICE.json"
