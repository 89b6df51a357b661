#!/bin/sh
# geo_train from the command line on the in-memory synthetic world (both builds): trains, validates,
# checkpoints and resolves its best checkpoint; no data files. The run is the fixture of the tests
# that need a finished run (export_refuses.sh, never_replace_inputs.sh).
#   in_memory_run.sh GEO_TRAIN RUN_DIR
set -eu
train="$1"; run="$2"
rm -rf "$run"
"$train" --config smoke.yaml --run-dir "$run" --set data.format=synthetic data.synthetic.drives=1 \
  data.synthetic.frames_per_drive=8 stages.0.iterations=2 stages.1.iterations=2 logging.interval=1 \
  logging.val_interval=2 logging.checkpoint_interval=2 logging.summary_interval=2
test -f "$run/checkpoints/best-stage2.pt" || { echo "no best-stage2.pt in $run"; exit 1; }
grep -q '^1,stage2,2,' "$run/metrics.csv" || { echo "no stage2 iteration 2 in $run/metrics.csv"; exit 1; }
