#!/usr/bin/env bash
# The README's main job: set up, then run what exists of the pipeline on built-in synthetic data.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
BUILD_DIR="${GEO_BUILD_DIR:-build}"
echo
echo "== geo demo =="
echo "Networks of the paper (parameter counts, FR on and off):"
"$BUILD_DIR/apps/geo_bench" --summary
echo
echo "Not yet available (see the issue tracker): geo_synth (synthetic KITTI world), geo_train,"
echo "geo_eval, geo_infer. When they land this script generates a world, trains both stages,"
echo "evaluates all three splits and prints the results table."
