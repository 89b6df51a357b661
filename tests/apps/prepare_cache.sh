#!/bin/sh
# geo_prepare packs a training split into a cache that the trainer's data layer reads back with
# data.root (the same snippet counts), and a missing --out is an error, not an empty cache.
#   prepare_cache.sh APPS_DIR WORK_DIR
set -eu
apps="$1"; work="$2"; rm -rf "$work"; mkdir -p "$work"
world="data.synthetic.drives=1 data.synthetic.frames_per_drive=8"
"$apps/geo_prepare" --config smoke.yaml --set data.format=synthetic $world --out "$work/cache" > "$work/log" 2>&1 ||
  { cat "$work/log"; exit 1; }
grep -q "synthetic data: 5 training snippets .* 1 validation" "$work/log" || { cat "$work/log"; exit 1; }
for part in train val; do
  test -s "$work/cache/$part/frames.bin" && test -s "$work/cache/$part/index.txt" || { echo "no $part/ in the cache"; exit 1; }
done
"$apps/geo_prepare" --config smoke.yaml --set data.root="$work/cache" --throughput --batches 2 > "$work/log" 2>&1 ||
  { cat "$work/log"; exit 1; }
grep -q "packed data: 5 training snippets .* 1 validation" "$work/log" || { cat "$work/log"; exit 1; }
grep -q "loader: .* samples/s (2 batches of 2" "$work/log" || { cat "$work/log"; exit 1; }
if "$apps/geo_prepare" --config smoke.yaml --set data.format=synthetic $world > "$work/log" 2>&1; then
  echo "geo_prepare without --out succeeded"; exit 1
fi
grep -q "give --out DIR" "$work/log" || { cat "$work/log"; exit 1; }
echo "geo_prepare wrote a cache that reads back with the same snippets"
