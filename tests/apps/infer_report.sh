#!/bin/sh
# geo_infer --report on five frames of a geo_synth drive: report.html shows the trajectory and, per
# frame, the input, the disparity and the flow, each an image file beside it named relatively, and
# fetches nothing (no URL, script or style sheet from elsewhere); the manifest lists what it added.
# With `browser`: Chromium (headless) opens it offline, every image loads (a copy missing one image
# is caught, so the check can fail) and a screenshot is written; exit 77 (skipped) without Chromium.
#   infer_report.sh APPS_DIR RUN_DIR WORK_DIR [browser]
set -eu
apps="$1"; run="$2"; w="$3"; mode="${4:-files}"
fail() { echo "FAIL: $1"; [ -f "$w/log" ] && cat "$w/log"; exit 1; }
if [ "$mode" = browser ]; then
  chromium=$(command -v chromium || command -v chromium-browser || true)
  [ -n "$chromium" ] || { echo "skipped: no chromium here (Debian: apt-get install chromium)"; exit 77; }
fi
rm -rf "$w"; mkdir -p "$w"
"$apps/geo_synth" --preset tiny --out "$w/world" --drives 1 --test-drives 1 --frames 5 --flow-pairs 0 \
  --odometry-frames 5 --threads 2 > "$w/log" 2>&1 || fail "geo_synth"
frames="$w/world/raw/2011_01_01/2011_01_01_drive_0001_sync/image_02/data"
"$apps/geo_infer" --checkpoint "$run" --input "$frames" --output "$w/out" --report --device cpu > "$w/log" 2>&1 \
  || fail "geo_infer --report"
r="$w/out/report.html"
[ -s "$r" ] || fail "no report.html"
if [ "$mode" = files ]; then
  n=0
  for s in $(grep -o 'src="[^"]*"' "$r" | sed 's/^src="//; s/"$//'); do
    [ -f "$w/out/$s" ] || fail "report.html shows '$s', which is not a file beside it"
    n=$((n + 1))
  done
  # trajectory.png, then five inputs, five disparities and four flows (the last frame has no next)
  [ "$n" -eq 15 ] || fail "report.html shows $n images, not 15"
  if grep -q -i -E 'https?:|src="/|href=|<script|<link|url\(' "$r"; then fail "report.html refers to something elsewhere"; fi
  for part in "<h2>Timing</h2>" "<th>camera</th>" "KITTI-like default" "5 frames, 208x64"; do
    grep -q -F "$part" "$r" || fail "report.html lacks '$part'"
  done
  for f in report.html 0000000000-input.jpg 0000000004-input.jpg; do
    grep -q -x -F "$f" "$w/out/geo_infer-outputs.txt" || fail "geo_infer-outputs.txt lacks $f"
  done
  echo "report.html: $n images, each a file beside it"
  exit 0
fi
# In a browser: a copy of the report with a script added (report.html has none) lists, once the
# page has loaded, the images that did not load; --dump-dom prints it.
loaded() {  # loaded FOLDER: what the check copy of FOLDER/report.html says
  sed 's|</body>|<script>window.addEventListener("load", () => { const bad = [...document.images].filter(i => !(i.complete \&\& i.naturalWidth > 0)).map(i => i.getAttribute("src")); document.body.setAttribute("data-check", bad.length ? "MISSING " + bad.join(" ") : "ALL " + document.images.length + " IMAGES LOADED"); });</script></body>|' \
    "$1/report.html" > "$1/check.html"
  "$chromium" --headless --no-sandbox --disable-gpu --disable-dev-shm-usage --no-first-run --user-data-dir="$w/profile" \
    --virtual-time-budget=10000 --dump-dom "file://$(cd "$1" && pwd)/check.html" 2> "$w/chromium.log" | grep -o 'data-check="[^"]*"' || true
}
got=$(loaded "$w/out")
if [ -z "$got" ]; then  # Chromium did not run (a machine without what it needs): not geo's failure
  tail -n 20 "$w/chromium.log"; echo "skipped: Chromium did not render the page here"; exit 77
fi
[ "$got" = 'data-check="ALL 15 IMAGES LOADED"' ] || { cat "$w/chromium.log"; fail "in Chromium: ${got:-no answer}"; }
cp -r "$w/out" "$w/broken"
rm "$w/broken/0000000002-disp.png"
got=$(loaded "$w/broken")
[ "$got" = 'data-check="MISSING 0000000002-disp.png"' ] || { cat "$w/chromium.log"; fail "a missing image went unnoticed (${got:-no answer}): the check cannot fail"; }
"$chromium" --headless --no-sandbox --disable-gpu --disable-dev-shm-usage --no-first-run --user-data-dir="$w/profile" --window-size=1100,1600 \
  --screenshot="$w/report.png" "file://$(cd "$w/out" && pwd)/report.html" > "$w/chromium.log" 2>&1 || true
[ -s "$w/report.png" ] || { cat "$w/chromium.log"; fail "no screenshot"; }
echo "report.html loads in $("$chromium" --version 2>/dev/null || echo Chromium) with all 15 images; screenshot $w/report.png"
