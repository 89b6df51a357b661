#!/bin/sh
# geo_export never replaces its input (best-<stage>.pt is a hard link to a checkpoint) nor, without
# --force, another training checkpoint; replacing an earlier model file is fine.
#   export_refuses.sh GEO_EXPORT RUN_DIR (a finished run: in_memory_run.sh)
set -eu
export_tool="$1"; run="$2"; work="$run"; ck="$run/checkpoints"
. "$(dirname "$0")/refused.sh"
sum=$(cksum < "$ck/best-stage2.pt")
refused "is the checkpoint being exported" "$export_tool" --checkpoint "$run" --out "$ck/best-stage2.pt"
[ "$(cksum < "$ck/best-stage2.pt")" = "$sum" ] || { echo "best-stage2.pt changed"; exit 1; }
refused "not a geo_export model file" "$export_tool" --checkpoint "$run" --out "$ck/stage1-00000002.pt"
"$export_tool" --checkpoint "$run" --out "$run/model.pt"
"$export_tool" --checkpoint "$run" --out "$run/model.pt"
