#!/usr/bin/env bash
# The FR ablation (the paper's Table 4) on the synthetic world: the demo's two-stage training
# (configs/demo.yaml) at a longer schedule (stage 1 240 iterations, stage 2 200, batch 4, all cores)
# with feature refinement on and off, same seed, same data, same iterations; then depth (Eigen
# protocol on the held-out drive) and flow (full and rigid, background and moving cars) side by
# side. About 15 minutes on 2 cores once built.
#   scripts/ablation.sh                    FR on vs off
#   GEO_ABLATION_DIR=out/ablation          where the world, runs and results go
#   GEO_ABLATION_SETS="stages.1.iterations=400"   extra --set overrides for both runs
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${GEO_ABLATION_DIR:-out/ablation}"
BIN="${GEO_BUILD_DIR:-build}/apps"
scripts/setup.sh
mkdir -p "$OUT"
if [ ! -f "$OUT/world/README.txt" ]; then
  "$BIN/geo_synth" --preset tiny --seed 1 --out "$OUT/world" --force
fi
# The schedule the README's ablation figures were measured with.
EXTRA=(--set stages.0.iterations=240 --set stages.0.batch_size=4
       --set stages.1.iterations=200 --set stages.1.batch_size=4 --set stages.1.learning_rate=2.0e-4
       --set run.threads=0 --set logging.summary_interval=120 --set logging.checkpoint_interval=120
       --set logging.val_interval=120)
for s in ${GEO_ABLATION_SETS:-}; do EXTRA+=(--set "$s"); done
for fr in on off; do
  use_fr=true
  [ "$fr" = off ] && use_fr=false
  echo "== training with FR $fr (configs/demo.yaml, model.use_fr=$use_fr) =="
  rm -rf "$OUT/run-fr-$fr"
  "$BIN/geo_train" --config configs/demo.yaml --set "data.root=$OUT/world/raw" --set "model.use_fr=$use_fr" \
    "${EXTRA[@]}" --run-dir "$OUT/run-fr-$fr"
  for split in eigen kitti2015; do
    mkdir -p "$OUT/results/$split"
    "$BIN/geo_eval" --split $split --data-root "$OUT/world" --checkpoint "$OUT/run-fr-$fr" \
      --output "$OUT/results/$split/fr-$fr.json" > /dev/null
  done
done
echo
echo "================ FR ablation on the synthetic world (held-out data) ================"
for split in eigen kitti2015; do
  echo "--- $split ---"
  "$BIN/geo_eval" --compare "$OUT/results/$split/fr-on.json" "$OUT/results/$split/fr-off.json"
done
