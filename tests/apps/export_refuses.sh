#!/bin/sh
# geo_export never replaces its input (best-<stage>.pt is a hard link to a checkpoint) nor, without
# --force, another training checkpoint; replacing an earlier model file is fine. int8 (below).
#   export_refuses.sh GEO_EXPORT RUN_DIR [FRAMES] (a finished run: in_memory_run.sh; FRAMES: a folder)
set -eu
export_tool="$1"; run="$2"; work="$run"; ck="$run/checkpoints"
. "$(dirname "$0")/refused.sh"
sum=$(cksum < "$ck/best-stage2.pt")
refused "is the checkpoint being exported" "$export_tool" --checkpoint "$run" --out "$ck/best-stage2.pt"
[ "$(cksum < "$ck/best-stage2.pt")" = "$sum" ] || { echo "best-stage2.pt changed"; exit 1; }
refused "not a geo_export model file" "$export_tool" --checkpoint "$run" --out "$ck/stage1-00000002.pt"
"$export_tool" --checkpoint "$run" --out "$run/model.pt"
"$export_tool" --checkpoint "$run" --out "$run/model.pt"
# int8: calibrated on frames, kept in the file with the int8 kernels; --int8 without frames, frames without --int8 refused.
refused "needs --calibration" "$export_tool" --checkpoint "$run" --out "$run/int8.pt" --int8
refused "it needs --int8" "$export_tool" --checkpoint "$run" --out "$run/int8.pt" --calibration "$run"
if [ -n "${3:-}" ]; then  # a folder of frames (a build with OpenCV)
  "$export_tool" --checkpoint "$run" --out "$run/int8.pt" --int8 --calibration "$3" --calibration-frames 3 > "$work/out.log" 2>&1 ||
    { cat "$work/out.log"; exit 1; }
  grep -q "int8: calibrated on 3 frame(s)" "$work/out.log" || { cat "$work/out.log"; exit 1; }
  grep -q "differs by at most 0 " "$work/out.log" || { cat "$work/out.log"; exit 1; }
  # ... as its int8 kernels instead of the float ones: under half the float file.
  grep -q "int8 weights" "$work/out.log" || { cat "$work/out.log"; exit 1; }
  [ "$(wc -c < "$run/int8.pt")" -lt "$(( $(wc -c < "$run/model.pt") / 2 ))" ] ||
    { echo "int8.pt is not under half of model.pt"; ls -l "$run"; exit 1; }
fi
