#!/bin/sh
# Options that would be accepted and silently ignored are refused, naming them: --resume with
# --init or --run-dir, --compare beside an evaluation's options, --camera-height without
# --scaling camera-height, camera-height scaling of flow, a negative geo_bench --train-batch.
#   ignored_options.sh APPS_DIR WORK_DIR
set -u
apps="$1"; work="$2"; mkdir -p "$work"
refused() {  # refused "expected message" command...
  want="$1"; shift
  if "$@" > "$work/out.log" 2>&1; then echo "accepted: $*"; exit 1; fi
  grep -q -- "$want" "$work/out.log" || { echo "no '$want' for: $*"; cat "$work/out.log"; exit 1; }
}
refused "--resume excludes --init\\|--init excludes --resume" "$apps/geo_train" --resume "$work" --init "$work/x.pt"
refused "--resume excludes --run-dir\\|--run-dir excludes --resume" "$apps/geo_train" --resume "$work" --run-dir "$work/r"
refused "--split excludes --compare\\|--compare excludes --split" "$apps/geo_eval" --compare a.json b.json --split eigen
refused "excludes --compare\|--compare excludes" "$apps/geo_eval" --compare a.json --checkpoint x.pt
refused "--camera-height is used by --scaling camera-height only (the scaling is 'median')" \
  "$apps/geo_eval" --split eigen --trivial --camera-height 1.5 --data-root "$work"
refused "--scaling camera-height is for --split eigen and odometry" \
  "$apps/geo_eval" --split kitti2015 --trivial --scaling camera-height --data-root "$work"
refused "--train-batch: must be >= 1 (got -3)" "$apps/geo_bench" --train-batch -3
echo "every ignored option refused"
