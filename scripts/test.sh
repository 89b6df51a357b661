#!/usr/bin/env bash
# The README's test command: set up (install + build), then run the whole suite.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
BUILD_DIR="${GEO_BUILD_DIR:-build}"
cd "$BUILD_DIR"
ctest --output-on-failure -j "${GEO_TEST_JOBS:-2}" "$@"
