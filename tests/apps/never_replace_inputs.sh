#!/bin/sh
# geo_eval, geo_bench, geo_train and geo_prepare write only where nothing they read is: --output naming the
# evaluated checkpoint or its split file, --export-gt naming the predictions, --json over a model or
# a clip of the config, or two outputs on one path are refused before any work, and the files stay
# byte for byte as they were.
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
# Every file a command reads is guarded, not only the model: predictions, split files, clips (kept
# outside the data root, which is guarded whole).
g="$run-guard"
mkdir -p "$g/preds"
printf 'mine\n' > "$g/preds/keep.txt"
printf '2011_01_01/2011_01_01_drive_0001_sync 2 l\n' > "$g/split.txt"
printf 'not a video\n' > "$g/clip.avi"
if "$apps/geo_eval" --split eigen --predictions "$g/preds" --data-root "$run" --export-gt "$g/preds" \
  > "$run/never_replace.log" 2>&1; then
  fail "geo_eval --export-gt over its --predictions succeeded"
fi
grep -q -- "--export-gt '$g/preds' is '$g/preds', which this command reads" "$run/never_replace.log" || fail "geo_eval --export-gt: no clear error"
if "$apps/geo_eval" --split eigen --checkpoint "$run" --data-root "$run" --split-file "$g/split.txt" \
  --output "$g/split.txt" > "$run/never_replace.log" 2>&1; then
  fail "geo_eval --output over its --split-file succeeded"
fi
grep -q -- "--output '$g/split.txt' is '$g/split.txt', which this command reads" "$run/never_replace.log" || fail "geo_eval --split-file: no clear error"
if "$apps/geo_bench" --summary --config video.yaml --set "data.videos=[$g/clip.avi]" --json "$g/clip.avi" \
  > "$run/never_replace.log" 2>&1; then
  fail "geo_bench --json over a clip of its config succeeded"
fi
grep -q -- "--json '$g/clip.avi' is '$g/clip.avi', which this command reads" "$run/never_replace.log" || fail "geo_bench data.videos: no clear error"
# geo_train and geo_prepare too: a run folder that is a clip's frame folder, a cache written over
# its data root, refused before anything is written there.
work="$g"
. "$(dirname "$0")/refused.sh"
mkdir -p "$g/frames" "$g/world"
cp "$(ls "$run"/summaries/*.png | head -n 1)" "$g/frames/000000.png"
refused "\-\-run-dir '$g/frames' is '$g/frames', which this command reads" \
  "$apps/geo_train" --config video.yaml --set "data.videos=[$g/frames]" --run-dir "$g/frames"
test "$(ls "$g/frames")" = 000000.png || fail "geo_train wrote into the clip's frame folder"
refused "\-\-out '$g/world' is '$g/world', which this command reads" \
  "$apps/geo_prepare" --config smoke.yaml --set "data.root=$g/world" --out "$g/world"
test -z "$(ls "$g/world")" || fail "geo_prepare wrote into its data root"
test "$(cat "$g/preds/keep.txt")" = mine || fail "the predictions changed"
test "$(cat "$g/split.txt")" = "2011_01_01/2011_01_01_drive_0001_sync 2 l" || fail "the split file changed"
test "$(cat "$g/clip.avi")" = "not a video" || fail "the clip changed"
rm -rf "$g"
test "$(cksum < "$ck")" = "$sum" || fail "the checkpoint changed"
echo "outputs over inputs refused; $ck unchanged"
