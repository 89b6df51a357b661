#!/usr/bin/env bash
# The README's main job, on a fresh Debian 12 machine: set up and build, render a small synthetic
# KITTI-format world (geo_synth), train stage 1 and stage 2 (configs/demo.yaml), evaluate the three
# splits (Eigen depth, KITTI-2015-style flow, odometry pose) against an untrained network and
# trivial baselines, run geo_infer on a held-out clip, and print the results.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${GEO_DEMO_DIR:-out/demo}"
echo "geo demo: about 10 minutes on 2 cores from a fresh machine (packages ~1 min, building the"
echo "training tools ~4 min, training ~3.5 min while the evaluation tools build beside it, evaluation"
echo "~0.5 min). Output: $OUT"
# The tools only (scripts/test.sh builds the tests), with OpenCV: the demo reads and writes images,
# also from a build folder configured without it (e.g. by GEO_OPENCV=0 scripts/test.sh).
GEO_OPENCV=1 GEO_TARGETS="geo_synth geo_train" scripts/setup.sh
BIN="${GEO_BUILD_DIR:-build}/apps"
mkdir -p "$OUT"
# Training at 64x208 gains little from a second thread (configs/demo.yaml: run.threads 1), so the
# evaluation tools build on the other core meanwhile, in their own process group (stopped with the demo).
echo "geo demo: building geo_eval and geo_infer beside the training (log: $OUT/build-eval-tools.log)"
GEO_OPENCV=1 GEO_JOBS=1 GEO_TARGETS="geo_eval geo_infer" setsid scripts/setup.sh > "$OUT/build-eval-tools.log" 2>&1 &
build_job=$!
trap 'kill -- -"$build_job" 2>/dev/null || true' EXIT
if [ ! -f "$OUT/world/README.txt" ]; then
  echo "== 1/4 rendering the synthetic world (geo_synth --preset tiny) =="
  "$BIN/geo_synth" --preset tiny --seed 1 --out "$OUT/world" --force
fi
echo "== 2/4 training stage 1 (depth + pose) and stage 2 (the residual FlowNet on the rigid flow) =="
rm -rf "$OUT/run"
"$BIN/geo_train" --config configs/demo.yaml --set "data.root=$OUT/world/raw" --run-dir "$OUT/run"
if ! wait "$build_job"; then
  cat "$OUT/build-eval-tools.log" >&2
  echo "geo demo: building geo_eval and geo_infer failed (log above)" >&2
  exit 1
fi
echo "== 3/4 evaluating: trained vs untrained network vs trivial baseline =="
# One split per core: each evaluation runs on one thread.
export OMP_NUM_THREADS=1
evaluate() {
  local split=$1
  mkdir -p "$OUT/results/$split"
  "$BIN/geo_eval" --split "$split" --data-root "$OUT/world" --checkpoint "$OUT/run" \
    --output "$OUT/results/$split/trained.json" > /dev/null
  "$BIN/geo_eval" --split "$split" --data-root "$OUT/world" --untrained configs/demo.yaml \
    --output "$OUT/results/$split/untrained.json" > /dev/null
  "$BIN/geo_eval" --split "$split" --data-root "$OUT/world" --trivial \
    --output "$OUT/results/$split/trivial.json" > /dev/null
  if [ "$split" = eigen ]; then
    # Metric depth without ground truth: the scale from the camera's height above the road (the
    # world records it: camera_height.txt, 1.65 m).
    "$BIN/geo_eval" --split eigen --data-root "$OUT/world" --checkpoint "$OUT/run" --scaling camera-height \
      --output "$OUT/results/eigen/camera-height.json" > /dev/null
  fi
}
evaluate eigen & eigen_job=$!
evaluate kitti2015
wait "$eigen_job"
echo "== 4/4 geo_infer on the held-out test drive, beside the odometry evaluation =="
evaluate odometry & odometry_job=$!
"$BIN/geo_infer" --checkpoint "$OUT/run" --max-frames 20 \
  --input "$OUT/world/raw/2011_01_01/2011_01_01_drive_0004_sync/image_02/data" --output "$OUT/infer"
wait "$odometry_job"
echo
echo "================ results on held-out synthetic data ================"
echo "(lower is better except a1..a3; trivial = constant depth / zero flow / no motion)"
for split in eigen kitti2015 odometry; do
  echo
  echo "--- $split ---"
  extra=()
  [ "$split" = eigen ] && extra=("$OUT/results/eigen/camera-height.json")
  "$BIN/geo_eval" --compare "$OUT/results/$split/trained.json" "${extra[@]}" "$OUT/results/$split/untrained.json" \
    "$OUT/results/$split/trivial.json"
done
echo "(camera-height: the trained model's depth scaled by the camera's height above the fitted road, no ground truth)"
echo
echo "Pictures: $OUT/run/summaries (training), $OUT/infer (disparity, flow per frame, trajectory.txt)"
echo "Metrics per iteration: $OUT/run/metrics.csv, validation: $OUT/run/val.csv"
echo "TensorBoard (losses, learning rate, validation, summary images): tensorboard --logdir $OUT"
