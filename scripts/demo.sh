#!/usr/bin/env bash
# The README's main job, on a fresh Debian 12 machine: set up and build, render a small synthetic
# KITTI-format world (geo_synth), train stage 1 and stage 2 (configs/demo.yaml), evaluate the three
# splits (Eigen depth, KITTI-2015-style flow, odometry pose) against an untrained network and
# trivial baselines, run geo_infer on a held-out clip, and print the results.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${GEO_DEMO_DIR:-out/demo}"
echo "geo demo: about 8 minutes on 2 cores from a fresh machine (packages ~1.5 min, building the"
echo "training tools ~2.5 min, training ~3.5 min while the evaluation tools build beside it, evaluation"
echo "~0.5 min). Output: $OUT"
# The tools only (scripts/test.sh builds the tests), with OpenCV: the demo reads and writes images,
# also from a build folder configured without it (e.g. by GEO_OPENCV=0 scripts/test.sh).
GEO_OPENCV=1 GEO_TARGETS="geo_synth geo_train" scripts/setup.sh
BIN="${GEO_BUILD_DIR:-build}/apps"
mkdir -p "$OUT"
if [ ! -f "$OUT/world/README.txt" ]; then
  echo "== 1/4 rendering the synthetic world (geo_synth --preset tiny) =="
  "$BIN/geo_synth" --preset tiny --seed 1 --out "$OUT/world" --force
fi
# Each evaluation on one thread (two run at a time, or one beside the training).
export OMP_NUM_THREADS=1
# eval_split SPLIT NAME ARGS...: one geo_eval run, its JSON in $OUT/results/SPLIT/NAME.json
eval_split() {
  local split=$1 name=$2
  shift 2
  mkdir -p "$OUT/results/$split"
  "$BIN/geo_eval" --split "$split" --data-root "$OUT/world" "$@" --output "$OUT/results/$split/$name.json" > /dev/null
}
# Training at 64x208 gains little from a second thread (configs/demo.yaml: run.threads 1), so the
# other core builds the evaluation tools meanwhile and scores the baselines (an untrained network,
# constant depth / zero flow / no motion), in a process group of its own that ends with the demo.
echo "geo demo: building geo_eval and geo_infer and scoring the baselines beside the training (log: $OUT/beside-training.log)"
set -m
{
  GEO_OPENCV=1 GEO_JOBS=1 GEO_TARGETS="geo_eval geo_infer" scripts/setup.sh
  export OMP_NUM_THREADS=1  # one core for this block: the training has the other
  for split in eigen kitti2015 odometry; do
    eval_split "$split" untrained --untrained configs/demo.yaml
    eval_split "$split" trivial --trivial
  done
} > "$OUT/beside-training.log" 2>&1 &
beside=$!
set +m
trap 'kill -- -"$beside" 2>/dev/null || true' EXIT
echo "== 2/4 training stage 1 (depth + pose) and stage 2 (the residual FlowNet on the rigid flow) =="
rm -rf "$OUT/run"
"$BIN/geo_train" --config configs/demo.yaml --set "data.root=$OUT/world/raw" --run-dir "$OUT/run"
if ! wait "$beside"; then
  cat "$OUT/beside-training.log" >&2
  echo "geo demo: building geo_eval/geo_infer or scoring the baselines failed (log above)" >&2
  exit 1
fi
echo "== 3/4 evaluating the trained network =="
# Metric depth without ground truth (camera-height): the scale from the camera's height above the
# road (the world records it: camera_height.txt, 1.65 m).
{ eval_split eigen trained --checkpoint "$OUT/run"
  eval_split eigen camera-height --checkpoint "$OUT/run" --scaling camera-height; } &
depth_job=$!
eval_split kitti2015 trained --checkpoint "$OUT/run"
wait "$depth_job"
echo "== 4/4 geo_infer on the held-out test drive, beside the odometry evaluation =="
eval_split odometry trained --checkpoint "$OUT/run" &
odometry_job=$!
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
