#!/usr/bin/env bash
# The GPU check, for anyone with a CUDA GPU and PyTorch 2.x installed (python3 -c 'import torch'):
#   1. builds geo against that PyTorch's LibTorch in build-gpu/ (scripts/setup.sh, GEO_TORCH=python;
#      without OpenCV unless its C++ package is installed),
#   2. runs the CUDA tests (tests/cuda: the fp32 CUDA step against the CPU step, resume on CUDA,
#      checkpoints moving between CUDA and CPU) and then the whole suite on that build,
#   3. trains the smoke config on the in-memory synthetic world on CUDA (both stages, validation,
#      checkpoints, resume-ready run folder) and prints its speed from metrics.csv,
#   4. runs scripts/bench.sh cuda (training steps, inference, peak memory) into build-gpu/bench/.
# Record what it prints, with the GPU, driver, CUDA and PyTorch versions, beside the figures.
#   GEO_TORCH / GEO_BUILD_DIR / GEO_OPENCV as for scripts/setup.sh (defaults python, build-gpu, auto)
set -euo pipefail
cd "$(dirname "$0")/.."
export GEO_TORCH="${GEO_TORCH:-python}"
export GEO_BUILD_DIR="${GEO_BUILD_DIR:-build-gpu}"
python3 -c 'import torch; assert torch.cuda.is_available(), "torch.cuda.is_available() is False"; print("geo gpu check: PyTorch", torch.__version__, "CUDA", torch.version.cuda, "cuDNN", torch.backends.cudnn.version(), "on", torch.cuda.get_device_name(0))'
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader || true
scripts/setup.sh

echo "geo gpu check: CUDA tests"
(cd "$GEO_BUILD_DIR" && ctest --output-on-failure -R '^Cuda\.')
echo "geo gpu check: the whole suite on this build"
(cd "$GEO_BUILD_DIR" && ctest --output-on-failure -j "${GEO_TEST_JOBS:-4}")

echo "geo gpu check: training on CUDA (smoke config, in-memory synthetic world)"
RUN="$GEO_BUILD_DIR/gpu_check_run"
rm -rf "$RUN"
"$GEO_BUILD_DIR/apps/geo_train" --config smoke.yaml --device cuda --run-dir "$RUN" --set data.format=synthetic
echo "geo gpu check: checkpoints in $RUN/checkpoints, losses in $RUN/metrics.csv"

echo "geo gpu check: benchmarks"
scripts/bench.sh cuda
