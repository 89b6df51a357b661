#!/usr/bin/env bash
# Sets up a fresh Debian 12 machine and builds geo (Release) into build/. Idempotent: packages
# already installed are not touched, `apt-get update` runs at most once, a configured build is
# only rebuilt incrementally. Works as root or through sudo.
#   GEO_BUILD_DIR   build folder (default: build)
#   GEO_JOBS        parallel compile jobs (default: number of cores)
#   GEO_WERROR=1    compiler warnings in geo's own code are errors (CI sets it)
#   GEO_SETUP_PACKAGES_ONLY=1  install the packages, build nothing (scripts/fuzz.sh)
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES=(
  libtorch-dev libopencv-dev libyaml-cpp-dev libcli11-dev libspdlog-dev
  libgtest-dev libgmock-dev
  libgloo-dev  # the headers of LibTorch's Gloo backend: multi-process training (train/distributed.h)
  libopenblas0-pthread  # without it Debian's LibTorch uses the reference BLAS: 17-25x slower matmuls
  cmake g++ make ccache
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "geo setup: installing ${missing[*]}"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { echo "geo setup: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
    SUDO="sudo"
  fi
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
else
  echo "geo setup: all packages present"
fi

if [ "${GEO_SETUP_PACKAGES_ONLY:-0}" = 1 ]; then
  exit 0
fi

BUILD_DIR="${GEO_BUILD_DIR:-build}"
JOBS="${GEO_JOBS:-$(nproc)}"
if [ ! -f "$BUILD_DIR/CMakeCache.txt" ]; then
  cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release
fi
if [ "${GEO_WERROR:-0}" = 1 ]; then
  cmake -S . -B "$BUILD_DIR" -DGEO_WERROR=ON >/dev/null
fi
echo "geo setup: building in $BUILD_DIR with $JOBS jobs (first build takes a while on 2 cores)"
cmake --build "$BUILD_DIR" -j "$JOBS"
echo "geo setup: done; tools are in $BUILD_DIR/apps"
