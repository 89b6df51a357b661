#!/bin/sh
# geo_eval and geo_bench write results only where nothing they read is: --output naming the
# evaluated checkpoint, --json over a model, or two outputs on one path are refused before any work,
# and the files stay byte for byte as they were.
#   never_replace_inputs.sh APPS_DIR RUN_DIR (a finished run: tests/CMakeLists.txt's in_memory_run)
set -eu
apps="$1"; run="$2"; ck="$run/checkpoints/best-stage2.pt"
sum=$(cksum < "$ck")
fail() { echo "$1"; cat "$run/never_replace.log"; exit 1; }
if "$apps/geo_eval" --split eigen --checkpoint "$run" --data-root "$run" --output "$ck" > "$run/never_replace.log" 2>&1; then
  fail "geo_eval --output over its checkpoint succeeded"
fi
grep -q "which this command reads: refusing to replace it" "$run/never_replace.log" || fail "geo_eval: no clear error"
if "$apps/geo_eval" --split odometry --checkpoint "$run" --data-root "$run" --output "$run/x.json" \
  --output-poses "$run/x.json" > "$run/never_replace.log" 2>&1; then
  fail "geo_eval with --output and --output-poses on one path succeeded"
fi
grep -q -- "--output and --output-poses name one file" "$run/never_replace.log" || fail "geo_eval: no clear error"
if "$apps/geo_bench" --summary --json "$ck" > "$run/never_replace.log" 2>&1; then
  fail "geo_bench --json over a checkpoint succeeded"
fi
grep -q -- "--json '$ck' is a model or checkpoint" "$run/never_replace.log" || fail "geo_bench: no clear error"
test "$(cksum < "$ck")" = "$sum" || fail "the checkpoint changed"
echo "outputs over inputs refused; $ck unchanged"
