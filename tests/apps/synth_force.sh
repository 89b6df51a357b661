#!/bin/sh
# geo_synth --force replaces a world whole: nothing of the earlier, larger world stays to be scored
# with the new one; a folder that holds something else is never cleared.
#   synth_force.sh APPS_DIR WORK_DIR
set -eu
apps="$1"; work="$2"; rm -rf "$work"; mkdir -p "$work"
small="--drives 1 --test-drives 1 --frames 6 --odometry-frames 5 --threads 1"
"$apps/geo_synth" --out "$work/w" $small --flow-pairs 3 > "$work/log" 2>&1 || { cat "$work/log"; exit 1; }
test "$(ls "$work/w/kitti2015/training/image_2" | grep -c '_10.png$')" = 3
"$apps/geo_synth" --out "$work/w" $small --flow-pairs 1 --force > "$work/log" 2>&1 || { cat "$work/log"; exit 1; }
n=$(ls "$work/w/kitti2015/training/image_2" | grep -c '_10.png$')
test "$n" = 1 || { echo "$n flow pairs after --force with --flow-pairs 1"; exit 1; }
mkdir -p "$work/mine"; echo keep > "$work/mine/notes.txt"
if "$apps/geo_synth" --out "$work/mine" $small --flow-pairs 0 --force > "$work/log" 2>&1; then
  echo "--force cleared a folder that is not a geo_synth world"; exit 1
fi
grep -q "holds no world written by geo_synth" "$work/log" || { cat "$work/log"; exit 1; }
test "$(cat "$work/mine/notes.txt")" = keep
echo "geo_synth --force replaced the world whole and left other folders alone"
