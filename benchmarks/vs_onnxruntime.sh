#!/usr/bin/env bash
# geo against ONNX Runtime's CPU engine (benchmarks/vs_onnxruntime.py says what is run): installs
# onnxruntime-node from the npm registry into bench-vs-pytorch/onnxruntime (its CPU library ships in
# the package; --ignore-scripts skips the install script, which fetches GPU providers from NuGet),
# builds geo_bench and the Python module, exports the DepthNets with torch.onnx.export and times
# them interleaved. Not part of CI (a few minutes of a quiet machine).
#   benchmarks/vs_onnxruntime.sh [--rounds 3 --iters 9 --threads 2 --height 128 --width 416]
# Writes bench-vs-pytorch/onnxruntime.md and prints it.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD="${GEO_BUILD_DIR:-build}"
ORT=bench-vs-pytorch/onnxruntime
command -v node >/dev/null || { echo "vs_onnxruntime: needs Node.js and npm (Debian: nodejs npm)" >&2; exit 1; }
if [ ! -f "$ORT/node_modules/onnxruntime-node/package.json" ]; then
  mkdir -p "$ORT"
  echo "vs_onnxruntime: installing onnxruntime-node into $ORT"
  (cd "$ORT" && npm install --ignore-scripts --no-audit --no-fund onnxruntime-node >/dev/null)
fi
GEO_BUILD_DIR="$BUILD" GEO_TARGETS="geo_bench geo_python" scripts/setup.sh >/dev/null
exec /usr/bin/python3 benchmarks/vs_onnxruntime.py --build "$BUILD" --ort "$ORT" "$@"
