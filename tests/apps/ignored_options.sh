#!/bin/sh
# Options that would be accepted and silently ignored are refused, naming them: --resume with
# --init or --run-dir, --compare beside an evaluation's options, --camera-height without
# --scaling camera-height, camera-height scaling of flow, geo_eval's --calibration without
# --precision int8 (and int8 without a model or frames), a negative geo_bench --train-batch; and
# sizes that would not fit are refused where they are read, naming them, before any allocation or
# write (geo_bench batches and ceiling, geo_synth worlds beyond the disk, data sizes in a config).
#   ignored_options.sh APPS_DIR WORK_DIR
set -u
apps="$1"; work="$2"; mkdir -p "$work"
. "$(dirname "$0")/refused.sh"
refused "--resume excludes --init\\|--init excludes --resume" "$apps/geo_train" --resume "$work" --init "$work/x.pt"
refused "--resume excludes --run-dir\\|--run-dir excludes --resume" "$apps/geo_train" --resume "$work" --run-dir "$work/r"
refused "--split excludes --compare\\|--compare excludes --split" "$apps/geo_eval" --compare a.json b.json --split eigen
refused "excludes --compare\|--compare excludes" "$apps/geo_eval" --compare a.json --checkpoint x.pt
refused "--camera-height is used by --scaling camera-height only (the scaling is 'median')" \
  "$apps/geo_eval" --split eigen --trivial --camera-height 1.5 --data-root "$work"
refused "--scaling camera-height is for --split eigen and odometry" \
  "$apps/geo_eval" --split kitti2015 --trivial --scaling camera-height --data-root "$work"
refused "--calibration calibrates int8: it needs --precision int8" \
  "$apps/geo_eval" --split eigen --trivial --calibration "$work" --data-root "$work"
refused "--precision int8 is a model's" \
  "$apps/geo_eval" --split eigen --trivial --precision int8 --calibration "$work" --data-root "$work"
refused "--train-batch: Value -3 not in range 1 to 1024" "$apps/geo_bench" --train-batch -3
refused "--batch: Value 100000 not in range 1 to 1024" "$apps/geo_bench" --batch 100000
refused "--ceiling-size: Value 1000000 not in range 64 to 16384" "$apps/geo_bench" --ceiling-size 1000000
refused "--flow-pairs: Value 2000000000 not in range 0 to 100000" "$apps/geo_synth" --out "$work/w" --flow-pairs 2000000000
refused "--drives: Value 100000000 not in range 1 to 1000" "$apps/geo_synth" --out "$work/w" --drives 100000000
refused "this world needs about .* GB free: fewer --drives" "$apps/geo_synth" --out "$work/w" --drives 1000 --frames 100000
[ ! -e "$work/w" ] || { echo "geo_synth wrote $work/w before refusing"; exit 1; }
refused "'data.height' = 1048576 (from --set): must be a multiple of 8 (4 pyramid scales) in 16..4096" \
  "$apps/geo_train" --config smoke.yaml --set data.format=synthetic --set data.height=1048576 --run-dir "$work/r"
refused "'data.augment.scale_max' = 1e+300 (from --set): must be in \[1, 2\]" \
  "$apps/geo_train" --config smoke.yaml --set data.format=synthetic --set data.augment.scale_max=1e300 --run-dir "$work/r"
[ ! -e "$work/r" ] || { echo "geo_train made $work/r before refusing"; exit 1; }
echo "every ignored option and unbounded size refused"
