#!/usr/bin/env bash
# Sets up a fresh Debian 12 machine and builds geo (Release) into build/. Idempotent: packages
# already installed are not touched, `apt-get update` runs at most once, a configured build is
# only rebuilt incrementally. Works as root or through sudo.
#   GEO_BUILD_DIR   build folder (default: build)
#   GEO_JOBS        parallel compile jobs (default: number of cores)
#   GEO_WERROR=1    compiler warnings in geo's own code are errors (CI sets it)
#   GEO_UNITY       1: unity build, each library's sources compiled as one translation unit and the
#                   tests' in batches of 4, so that what LibTorch's headers instantiate is compiled
#                   once per batch (a fresh build in ~70% of the time; an edit recompiles its batch);
#                   0: one translation unit per source.
#                   Default: 1 for a new build folder, an existing one keeps its setting.
#   GEO_CXX         the C++ compiler of a new build folder: clang (default; installed with Debian's
#                   LibTorch, elsewhere the one on the PATH, else GCC) or gcc; an existing build
#                   folder keeps its compiler (scripts/compiler.sh says why Clang).
#   GEO_SETUP_PACKAGES_ONLY=1  install the packages, build nothing (scripts/fuzz.sh)
#   GEO_SETUP_OFFLINE=1  install nothing: for a machine without a package mirror whose libraries
#                   were put in place otherwise (an offline GPU image)
#   GEO_SETUP_BROWSER=0  do not install Chromium (only the browser test of geo_infer --report needs it)
#   GEO_TARGETS     build only these targets (space-separated, e.g. "geo_train geo_eval"; default: all,
#                   the tests included)
#   GEO_TORCH       which LibTorch to build against:
#                     system (default)  Debian's libtorch-dev (1.13, CPU)
#                     python            the one inside the PyTorch that `python3` imports (pip wheel,
#                                       CUDA on GPU machines): torch.utils.cmake_prefix_path
#                     /path/to/libtorch an unpacked LibTorch archive (holds share/cmake/Torch)
#   GEO_OPENCV      1: build the image tools (geo_eval, geo_infer, geo_synth, geo_prepare; installs
#                   libopencv-dev), 0: without OpenCV (geo_train trains from packed caches and the
#                   in-memory synthetic world, geo_bench, geo_export, the library). Default: 1 with
#                   the system LibTorch; with another LibTorch 1 only when OpenCV's C++ package is
#                   already installed (a PyTorch GPU image usually has none; ~220 MB of packages).
set -euo pipefail
cd "$(dirname "$0")/.."

. scripts/compiler.sh
installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }

TORCH="${GEO_TORCH:-system}"
TORCH_PREFIX=""
case "$TORCH" in
  system) ;;
  python)
    TORCH_PREFIX="$(python3 -c 'import torch; print(torch.utils.cmake_prefix_path)' 2>/dev/null)" ||
      { echo "geo setup: GEO_TORCH=python, but 'python3 -c \"import torch\"' fails: install PyTorch or use GEO_TORCH=system" >&2; exit 1; }
    ;;
  *)
    [ -d "$TORCH/share/cmake/Torch" ] ||
      { echo "geo setup: GEO_TORCH=$TORCH is not a LibTorch folder (no $TORCH/share/cmake/Torch); use system, python or such a folder" >&2; exit 1; }
    TORCH_PREFIX="$(cd "$TORCH" && pwd)"
    ;;
esac
OPENCV="${GEO_OPENCV:-}"
if [ -z "$OPENCV" ]; then
  if [ "$TORCH" = system ] || installed libopencv-dev; then OPENCV=1; else OPENCV=0; fi
fi

PACKAGES=(
  libyaml-cpp-dev libcli11-dev libspdlog-dev
  libgtest-dev libgmock-dev
)
# Build tools already on the PATH (a GPU image's cmake from pip, say) will do; ccache is optional
# away from Debian's LibTorch (an offline image may have none).
for tool in cmake g++ make; do command -v "$tool" >/dev/null || PACKAGES+=("$tool"); done
case "${GEO_CXX:-clang}" in
  clang | gcc) ;;
  *) echo "geo setup: GEO_CXX must be clang or gcc, not '$GEO_CXX'" >&2; exit 1 ;;
esac
# Clang from Debian with Debian's LibTorch; elsewhere (a GPU image) only the one on the PATH.
if [ "${GEO_CXX:-clang}" = clang ] && ! command -v clang++ >/dev/null; then
  if [ "$TORCH" = system ]; then PACKAGES+=(clang)
  elif [ -n "${GEO_CXX:-}" ]; then echo "geo setup: GEO_CXX=clang, but there is no clang++ on the PATH" >&2; exit 1; fi
fi
command -v ccache >/dev/null || { [ "$TORCH" != system ] || PACKAGES+=(ccache); }
# Ninja builds several targets at once (make builds the targets it is given one after another); one
# already on the PATH (a PyTorch image's) will do.
command -v ninja >/dev/null || PACKAGES+=(ninja-build)
if [ "$TORCH" = system ]; then
  # Debian's LibTorch: the CPU build (main), or its CUDA build where that is installed (contrib,
  # Debian 13: libtorch-cuda-dev, which conflicts with libtorch-dev; scripts/debian13.sh's CUDA root)
  # with its own Gloo and Python packages.
  if installed libtorch-cuda-dev; then TORCH_PACKAGES=(libtorch-cuda-dev libgloo-cuda-dev libnccl-dev python3-torch-cuda)
  else TORCH_PACKAGES=(libtorch-dev libgloo-dev python3-torch); fi
  PACKAGES+=(
    "${TORCH_PACKAGES[@]}"  # libgloo*-dev: the headers of LibTorch's Gloo backend (train/distributed.h)
    libopenblas0-pthread  # without it Debian's LibTorch uses the reference BLAS: 17-25x slower matmuls
    # The Python module (python/) on the same LibTorch, and its tests.
    python3-numpy python3-yaml python3-dev pybind11-dev python3-pytest python3-onnx
    clang-format  # the style check of the suite (Format.SourcesFollowClangFormat; clang-format 14 here)
  )
fi
if [ "$OPENCV" = 1 ]; then PACKAGES+=(libopencv-dev); fi
# Headless Chromium: the test that opens geo_infer's report.html in a browser
# (Apps.InferReportLoadsInABrowser, skipped without it); GEO_SETUP_BROWSER=0 leaves it out.
if [ "$OPENCV" = 1 ] && [ "$TORCH" = system ] && [ "${GEO_SETUP_BROWSER:-1}" = 1 ]; then PACKAGES+=(chromium); fi

missing=()
for p in "${PACKAGES[@]}"; do
  installed "$p" || missing+=("$p")
done
if ((${#missing[@]})) && [ "${GEO_SETUP_OFFLINE:-0}" = 1 ]; then
  echo "geo setup: GEO_SETUP_OFFLINE=1: not installing ${missing[*]} (CMake finds what is there, or says what is not)"
elif ((${#missing[@]})); then
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
CONFIGURE=(-DCMAKE_BUILD_TYPE=Release)
if [ "$OPENCV" = 1 ]; then CONFIGURE+=(-DGEO_WITH_OPENCV=ON); else CONFIGURE+=(-DGEO_WITH_OPENCV=OFF); fi
# With Debian's LibTorch the packages above hold everything the Python module needs: a module that
# cannot be built is then an error, not a quiet omission.
if [ "$TORCH" = system ]; then CONFIGURE+=(-DGEO_WITH_PYTHON=ON); fi
if [ -n "$TORCH_PREFIX" ]; then CONFIGURE+=("-DCMAKE_PREFIX_PATH=$TORCH_PREFIX"); fi
echo "geo setup: LibTorch $TORCH${TORCH_PREFIX:+ ($TORCH_PREFIX)}, OpenCV $OPENCV, build folder $BUILD_DIR"
if [ ! -f "$BUILD_DIR/CMakeCache.txt" ]; then
  [ -n "${GEO_UNITY:-}" ] || CONFIGURE+=(-DGEO_UNITY_BUILD=ON)
  CONFIGURE+=("-DCMAKE_CXX_COMPILER=$(geo_cxx)")
  CONFIGURE+=(-G Ninja)  # a new build folder; an existing one keeps its generator
  cmake -S . -B "$BUILD_DIR" "${CONFIGURE[@]}"
elif [ -n "${GEO_TORCH:-}${GEO_OPENCV:-}" ]; then
  cmake -S . -B "$BUILD_DIR" "${CONFIGURE[@]}" >/dev/null  # asked for explicitly: apply to an existing build
fi
CXX_USED="$(sed -n 's/^CMAKE_CXX_COMPILER:[A-Z]*=//p' "$BUILD_DIR/CMakeCache.txt")"
echo "geo setup: C++ compiler $CXX_USED"
if "$CXX_USED" --version | grep -q clang; then CXX_KIND=clang; else CXX_KIND=gcc; fi
if [ -n "${GEO_CXX:-}" ] && [ "$GEO_CXX" != "$CXX_KIND" ]; then
  echo "geo setup: GEO_CXX=$GEO_CXX, but $BUILD_DIR was configured with $CXX_USED: a build folder keeps its compiler (use another GEO_BUILD_DIR)" >&2
  exit 1
fi
if [ "$TORCH" = system ] && ! grep -q '^GEO_WITH_PYTHON:STRING=ON$' "$BUILD_DIR/CMakeCache.txt"; then
  cmake -S . -B "$BUILD_DIR" -DGEO_WITH_PYTHON=ON >/dev/null  # a build folder made before the module existed
fi
if [ "${GEO_WERROR:-0}" = 1 ]; then
  cmake -S . -B "$BUILD_DIR" -DGEO_WERROR=ON >/dev/null
fi
if [ -n "${GEO_UNITY:-}" ]; then
  cmake -S . -B "$BUILD_DIR" -DGEO_UNITY_BUILD="$([ "$GEO_UNITY" = 1 ] && echo ON || echo OFF)" >/dev/null
fi
TARGETS=()
for t in ${GEO_TARGETS:-}; do TARGETS+=(--target "$t"); done
echo "geo setup: building ${GEO_TARGETS:-everything} in $BUILD_DIR with $JOBS jobs (first build takes a while on 2 cores)"
cmake --build "$BUILD_DIR" -j "$JOBS" "${TARGETS[@]}"
echo "geo setup: done; tools are in $BUILD_DIR/apps"
