#!/usr/bin/env bash
# The README's test command: set up (install + build), then run the whole suite.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
BUILD_DIR="${GEO_BUILD_DIR:-build}"
cd "$BUILD_DIR"
# ctest runs tests side by side (-j) and each test's LibTorch uses every core: with OpenMP's default
# (threads spin while they wait) two such tests on 2 cores ran each training step ~3.5x slower than
# one after the other (geo_bench, docs/measured/ci-times.md). Waiting threads that sleep lose nothing.
export OMP_WAIT_POLICY="${OMP_WAIT_POLICY:-PASSIVE}"
ctest --output-on-failure -j "${GEO_TEST_JOBS:-2}" "$@"
