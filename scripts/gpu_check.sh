#!/usr/bin/env bash
# The GPU check, for anyone with a CUDA GPU and PyTorch 2.x installed (python3 -c 'import torch'):
#   1. builds geo against that PyTorch's LibTorch in build-gpu/ (scripts/setup.sh, GEO_TORCH=python;
#      without OpenCV unless its C++ package is installed),
#   2. runs the CUDA tests (tests/cuda: the fp32 CUDA step against the CPU step, resume on CUDA,
#      checkpoints moving between CUDA and CPU) and then the whole suite on that build,
#   3. trains the smoke config on the in-memory synthetic world on CUDA (both stages, validation,
#      checkpoints, resume-ready run folder) and prints its speed from metrics.csv,
#   4. runs scripts/bench.sh cuda (training steps at the paper's batch and size, replayed as CUDA
#      graphs, inference, the pipeline graphed and not, peak memory; TF32, the default
#      run.precision), the training steps again without CUDA graphs (run.cuda_graphs=false, with
#      the profile's top operators) and everything in bf16, into build-gpu/bench/,
#   5. times PyTorch's eager GeoNet port (benchmarks/geonet_pytorch.py --device cuda: DepthNet at
#      batch 1, the stage-1 step at batch 4) as the reference,
#   6. where this geo has NCCL, trains two processes over NCCL on the first GPU (NCCL itself may
#      refuse two ranks on one GPU: that is reported, not a failure of geo).
# Each step runs even when an earlier one failed; the summary at the end names the failed steps and
# the exit status is non-zero if any did. Record what it prints, with the GPU, driver, CUDA and
# PyTorch versions, beside the figures.
#   GEO_TORCH / GEO_BUILD_DIR / GEO_OPENCV / GEO_TARGETS / GEO_JOBS as for scripts/setup.sh
#                    (defaults python, build-gpu, auto, everything, all cores)
#   GEO_GPU_SUITE=0  skip the whole suite (step 2's second half; it takes the longest)
#   GEO_GPU_BF16=0   skip the bf16 benchmark;  GEO_GPU_NCCL=0  skip the two NCCL processes
#   GEO_GPU_LOG_DIR  also keep each step's log there (default: none)
set -uo pipefail
cd "$(dirname "$0")/.."
export GEO_TORCH="${GEO_TORCH:-python}"
export GEO_BUILD_DIR="${GEO_BUILD_DIR:-build-gpu}"
BUILD="$GEO_BUILD_DIR"
LOGS="${GEO_GPU_LOG_DIR:-}"
[ -z "$LOGS" ] || mkdir -p "$LOGS"
FAILED=()

# step NAME COMMAND...: runs COMMAND, its output also into $LOGS/NAME.log, and records a failure.
step() {
  local name="$1"; shift
  echo "geo gpu check: $name"
  local t0=$SECONDS rc
  if [ -n "$LOGS" ]; then "$@" 2>&1 | tee "$LOGS/$name.log"; rc=${PIPESTATUS[0]}; else "$@"; rc=$?; fi
  echo "geo gpu check: $name: $([ "$rc" = 0 ] && echo ok || echo "FAILED (exit $rc)") in $((SECONDS - t0)) s"
  [ "$rc" = 0 ] || FAILED+=("$name")
  return 0
}

python3 -c 'import torch; assert torch.cuda.is_available(), "torch.cuda.is_available() is False"; print("geo gpu check: PyTorch", torch.__version__, "CUDA", torch.version.cuda, "cuDNN", torch.backends.cudnn.version(), "on", torch.cuda.get_device_name(0))' || exit 1
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader || true
echo "geo gpu check: CPU $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2-), $(nproc) cores"

step build scripts/setup.sh
[ -x "$BUILD/apps/geo_train" ] || { echo "geo gpu check: no geo_train was built; stopping" >&2; exit 1; }

if [ -x "$BUILD/tests/cuda_tests" ]; then
  step cuda-tests bash -c "cd '$BUILD' && ctest --output-on-failure -R '^Cuda\.'"
fi
if [ "${GEO_GPU_SUITE:-1}" = 1 ]; then
  step suite bash -c "cd '$BUILD' && ctest --output-on-failure -j '${GEO_TEST_JOBS:-4}'"
fi

RUN="$BUILD/gpu_check_run"
rm -rf "$RUN"
step train-cuda "$BUILD/apps/geo_train" --config smoke.yaml --device cuda --run-dir "$RUN" --set data.format=synthetic
[ -f "$RUN/metrics.csv" ] && echo "geo gpu check: checkpoints in $RUN/checkpoints, losses and step times in $RUN/metrics.csv"

step bench-tf32 scripts/bench.sh cuda
step bench-eager env GEO_BENCH_OUT="$BUILD/bench/eager" scripts/bench.sh cuda --no-infer --no-comm \
  --set run.cuda_graphs=false --profile 15
[ "${GEO_GPU_BF16:-1}" = 1 ] && step bench-bf16 env GEO_BENCH_OUT="$BUILD/bench/bf16" scripts/bench.sh cuda --precision bf16
pytorch_eager() {
  python3 benchmarks/geonet_pytorch.py --device cuda --row depth --iters 20 &&
    python3 benchmarks/geonet_pytorch.py --device cuda --row step --iters 5
}
step pytorch-eager pytorch_eager

# Two processes over NCCL on GPU 0 (a machine with two GPUs would give each its own).
if [ "${GEO_GPU_NCCL:-1}" != 1 ]; then
  echo "geo gpu check: GEO_GPU_NCCL=0: no multi-process GPU check"
elif grep -q 'GEO_WITH_NCCL' "$BUILD/build.ninja" "$BUILD/src/CMakeFiles/geo_train_parts.dir/flags.make" 2>/dev/null; then
  nccl_pair() {
    local port pids=() rc=0
    port=$((29500 + RANDOM % 1000))
    rm -rf "$BUILD/gpu_check_nccl"
    for r in 0 1; do
      RANK=$r WORLD_SIZE=2 LOCAL_RANK=0 MASTER_ADDR=127.0.0.1 MASTER_PORT=$port timeout 300 \
        "$BUILD/apps/geo_train" --config smoke.yaml --device cuda:0 --run-dir "$BUILD/gpu_check_nccl" \
        --set data.format=synthetic --set run.distributed.backend=nccl --set run.distributed.timeout_s=120 &
      pids+=($!)
    done
    for p in "${pids[@]}"; do wait "$p" || rc=$?; done
    return $rc
  }
  step nccl-two-processes nccl_pair
else
  echo "geo gpu check: this geo has no NCCL (configure said NCCL OFF): no multi-process GPU check"
fi

if [ ${#FAILED[@]} -gt 0 ]; then
  echo "geo gpu check: FAILED steps: ${FAILED[*]}"
  exit 1
fi
echo "geo gpu check: all steps passed"
