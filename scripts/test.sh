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
# glibc's allocator on transparent huge pages, freed memory kept for reuse (what training does
# itself: keep_freed_memory, src/core/runtime.h): the tests start hundreds of LibTorch processes
# that touch fresh memory, and a page fault costs ~12 us on some virtual machines. Measured
# (docs/measured/ci-times.md): the suite without its two learning checks, 1526 -> 1062 CPU-seconds.
# Only speed changes; GLIBC_TUNABLES set beforehand is kept.
export GLIBC_TUNABLES="${GLIBC_TUNABLES-glibc.malloc.hugetlb=1:glibc.malloc.mmap_max=0:glibc.malloc.trim_threshold=18446744073709551615:glibc.malloc.top_pad=67108864}"
ctest --output-on-failure -j "${GEO_TEST_JOBS:-2}" "$@"
