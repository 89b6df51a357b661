#!/usr/bin/env bash
# Depth in stop-and-go traffic on the synthetic world (docs/video.md, "Moving things"): one traffic
# drive of 160 frames, written as a video, trains configs/video.yaml at the real-video check's size
# and schedule (ResNet-18 at 64x208, 400 iterations, lr 5e-4, batch 4, the camera given), once per
# variant and seed; each model is scored on the world's two held-out traffic drives (Eigen protocol,
# median scaling) beside a constant depth: AbsRel overall, on the moving objects, and on the cars
# that keep their distance to the camera (with_camera). About 5 minutes a training on 2 cores.
#   scripts/traffic_ablation.sh                          the variants below, seeds 42 and 2
#   GEO_TRAFFIC_SEEDS="42"                               training seeds
#   GEO_TRAFFIC_VARIANTS="automask prior=stages.0.weights.ground=0.2"
#                                                        name[=set[,set...]] each (video.yaml's defaults
#                                                        plus those --set overrides)
#   GEO_TRAFFIC_DIR=out/traffic                          where the world, runs and results go
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${GEO_TRAFFIC_DIR:-out/traffic}"
BIN="${GEO_BUILD_DIR:-build}/apps"
SEEDS="${GEO_TRAFFIC_SEEDS:-42 2}"
VARIANTS="${GEO_TRAFFIC_VARIANTS:-automask prior=stages.0.weights.ground=0.2}"
scripts/setup.sh
mkdir -p "$OUT/results"
if [ ! -f "$OUT/world/README.txt" ] || [ ! -f "$OUT/drive.avi" ]; then
  "$BIN/geo_synth" --preset tiny --traffic --seed 3 --frames 160 --drives 1 --test-drives 2 --flow-pairs 0 \
    --odometry-frames 5 --out "$OUT/world" --video "$OUT/drive.avi" --force
fi
# The camera of the tiny preset (src/data/synth/synth.h) and the real-video check's schedule.
COMMON=(--set "data.videos=[$OUT/drive.avi]" --set "data.camera.intrinsics=[120.8,123.1,102.1,29.5]"
        --set data.video.val_fraction=0 --set data.height=64 --set data.width=208 --set data.num_workers=1
        --set model.encoder_depth=18 --set model.bn_momentum=0.1 --set stages.0.iterations=400
        --set stages.0.learning_rate=5.0e-4 --set logging.interval=100 --set logging.summary_interval=0
        --set logging.checkpoint_interval=400 --set logging.val_interval=0 --set run.threads=0)
results=("$OUT/results/constant.json")
"$BIN/geo_eval" --split eigen --data-root "$OUT/world" --trivial --output "$OUT/results/constant.json" > /dev/null
for seed in $SEEDS; do
  for variant in $VARIANTS; do
    name="${variant%%=*}"
    sets=()
    if [ "$name" != "$variant" ]; then
      IFS=, read -r -a extra <<< "${variant#*=}"
      for s in "${extra[@]}"; do sets+=(--set "$s"); done
    fi
    run="$OUT/run-$name-$seed"
    echo "== $name, seed $seed: geo_train --config configs/video.yaml ${sets[*]} =="
    rm -rf "$run"
    "$BIN/geo_train" --config configs/video.yaml "${COMMON[@]}" ${sets[@]+"${sets[@]}"} --set "run.seed=$seed" \
      --run-dir "$run"
    "$BIN/geo_eval" --split eigen --data-root "$OUT/world" --checkpoint "$run" \
      --output "$OUT/results/$name-$seed.json" > /dev/null
    results+=("$OUT/results/$name-$seed.json")
  done
done
echo
echo "================ stop-and-go traffic (held-out drives, Eigen protocol, median scaling) ================"
"$BIN/geo_eval" --compare "${results[@]}"
