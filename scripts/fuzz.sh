#!/usr/bin/env bash
# The parsers' fuzz job (CI runs it after the test suite): builds tests/fuzz with AddressSanitizer
# and UBSan into build-asan/ and feeds every reader of outside data (calibration, split lists, pose
# files, Velodyne scans, flow/depth/image PNGs, packed cache, .npy, YAML) mutated inputs for a set
# time. Any out-of-bounds access, undefined behaviour, crash, hang or non-geo error fails it. Beside
# it, the int8 tests (tests/models/int8_test.cpp: the byte kernels and the three int8 networks at every
# kind of input size and calibration) under the same sanitizers: a memory error there fails the job.
#   GEO_FUZZ_SECONDS     seconds per target (default 20; 13 targets)
#   GEO_FUZZ_SEED        mutation seed (default fixed, so a failure reproduces)
#   GEO_FUZZ_BUILD_DIR   build folder (default build-asan)
#   GEO_JOBS             parallel compile jobs (default: number of cores)
#   GEO_FUZZ_BUILD_ONLY  1: build the sanitized fuzz tests and stop (CI builds them beside the suite)
set -euo pipefail
cd "$(dirname "$0")/.."
GEO_SETUP_PACKAGES_ONLY=1 scripts/setup.sh
BUILD_DIR="${GEO_FUZZ_BUILD_DIR:-build-asan}"
JOBS="${GEO_JOBS:-$(nproc)}"
if [ ! -f "$BUILD_DIR/CMakeCache.txt" ]; then
  # No -Werror here: GCC 12 warns falsely (maybe-uninitialized in <regex>) under the sanitizers.
  # -g1: line tables only, what the sanitizers' stack traces need (file:line of every frame); full
  # debug information took a third longer to build (64 s against 45 s for the networks' unity file).
  . scripts/compiler.sh  # the compiler as scripts/setup.sh chooses it
  cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DGEO_SANITIZE=address,undefined -DCMAKE_CXX_COMPILER="$(geo_cxx)" \
    -DCMAKE_CXX_FLAGS_RELEASE="-O1 -g1" -DGEO_WERROR=OFF -DGEO_UNITY_BUILD="$([ "${GEO_UNITY:-1}" = 1 ] && echo ON || echo OFF)"
fi
echo "geo fuzz: building the sanitized fuzz and int8 tests in $BUILD_DIR with $JOBS jobs"
cmake --build "$BUILD_DIR" -j "$JOBS" --target fuzz_tests models_tests
[ "${GEO_FUZZ_BUILD_ONLY:-0}" = 1 ] && exit 0
# LibTorch allocates for the process lifetime: leak reports would be its, not geo's.
export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:${ASAN_OPTIONS:-}"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:${UBSAN_OPTIONS:-}"
export GEO_FUZZ_SECONDS="${GEO_FUZZ_SECONDS:-20}"
echo "geo fuzz: $GEO_FUZZ_SECONDS s per target under ASan+UBSan, beside the int8 tests under the same sanitizers"
# The two run side by side (the fuzzing is one thread; the int8 tests keep the other core busy),
# each into its own log, shown whole when both are done. A hang is a failure too: each is bounded.
logs="$(mktemp -d)"
fuzz= int8=
trap 'kill $fuzz $int8 2>/dev/null || true; rm -rf "$logs"' EXIT
# libpng reports every corrupt input on stderr (~200k lines): left out of the log.
( set +o pipefail
  timeout --signal=KILL $((GEO_FUZZ_SECONDS * 13 + 300)) "$BUILD_DIR/tests/fuzz_tests" 2>&1 | grep -v "^libpng "
  exit "${PIPESTATUS[0]}" ) > "$logs/fuzz" 2>&1 &
fuzz=$!
timeout --signal=KILL 900 "$BUILD_DIR/tests/models_tests" --gtest_filter='Int8.*' > "$logs/int8" 2>&1 &
int8=$!
fuzz_status=0 int8_status=0
wait "$fuzz" || fuzz_status=$?
wait "$int8" || int8_status=$?
fuzz= int8=
echo "geo fuzz: the parsers' fuzz tests"
cat "$logs/fuzz"
echo "geo fuzz: the int8 tests under ASan+UBSan"
cat "$logs/int8"
[ "$fuzz_status" = 0 ] || { echo "geo fuzz: the fuzz tests failed (exit $fuzz_status)" >&2; exit 1; }
[ "$int8_status" = 0 ] || { echo "geo fuzz: the int8 tests failed (exit $int8_status)" >&2; exit 1; }
