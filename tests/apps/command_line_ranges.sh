#!/bin/sh
# Command-line values out of range say what is expected (not CLI11's "Value 0 not in range 0.000000
# to 1.797e308"), an empty value is named (every tool), and geo_eval (in builds with OpenCV) takes
# one source of predictions. geo_synth, geo_eval and geo_infer need OpenCV: builds without it have
# none of the three.
#   command_line_ranges.sh APPS_DIR WORK_DIR
set -eu
apps="$1"; work="$2"; mkdir -p "$work"
. "$(dirname "$0")/refused.sh"
refused "must be >= 1 (got 0)" "$apps/geo_bench" --iters 0
refused "must be auto, cpu, cuda or cuda:N (got 'gpu')" "$apps/geo_bench" --device gpu
refused "\-\-json '': an empty value (a path or name was expected)" "$apps/geo_bench" --summary --json ''
if [ -x "$apps/geo_eval" ]; then
  refused "\-\-out '': an empty value" "$apps/geo_synth" --out ''
  refused "trivial excludes --checkpoint\|checkpoint excludes --trivial" "$apps/geo_eval" --split eigen --trivial --checkpoint x.pt
  refused "must be > 0 (got 0)" "$apps/geo_eval" --split odometry --trivial --segment-lengths 0
  refused "\-\-output '': an empty value" "$apps/geo_infer" --checkpoint x.pt --input x.png --output ''
fi
echo "out-of-range values refused with what is expected"
