#!/usr/bin/env bash
# CI (ctest Install.*): installs geo into a temporary prefix, builds examples/depth_from_camera
# against the installed package (not the build tree), runs it on a geo_synth clip with a model that
# geo_export wrote, and checks that its depth maps equal geo_infer's byte for byte.
#   consume_installed.sh BUILD_DIR SOURCE_DIR
set -euo pipefail
BUILD=$(cd "$1" && pwd) SRC=$(cd "$2" && pwd)
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
cmake --install "$BUILD" --prefix "$T/prefix" > "$T/install.log"
cmake -S "$SRC/examples/depth_from_camera" -B "$T/example" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$T/prefix;${GEO_TORCH_PREFIX:-}" > "$T/configure.log"
cmake --build "$T/example" -j "${GEO_JOBS:-2}" > "$T/build.log"
# The example found the installed package, not the build tree.
grep -q "$T/prefix/lib/cmake/geo" "$T/example/CMakeCache.txt"
B="$T/prefix/bin"
"$B/geo_synth" --preset tiny --out "$T/world" --drives 1 --test-drives 1 --frames 8 --flow-pairs 1 \
  --odometry-frames 5 > /dev/null 2>&1
"$B/geo_train" --config smoke.yaml --set data.root="$T/world" stages[0].iterations=2 \
  stages[1].iterations=1 logging.val_interval=0 run.threads=2 --run-dir "$T/run" > "$T/train.log" 2>&1
"$B/geo_export" --checkpoint "$T/run" --out "$T/model.pt"
mkdir -p "$T/frames" "$T/infer" "$T/mine"
cp "$T"/world/raw/*/*drive_0002_sync/image_02/data/000000000[0-2].png "$T/frames/"
"$B/geo_infer" --checkpoint "$T/run" --input "$T/frames" --output "$T/infer" > /dev/null 2>&1
"$T/example/depth_from_camera" "$T/model.pt" "$T/frames" "$T/mine"
n=0
for f in "$T"/frames/*.png; do
  name=$(basename "$f" .png)
  cmp "$T/infer/$name-depth.png" "$T/mine/$name-depth.png"
  n=$((n + 1))
done
# Depth in metres from the camera height (or, for a model this short-trained, a clear "no road plane").
mkdir -p "$T/metric"
"$T/example/depth_from_camera" "$T/model.pt" "$T/frames" "$T/metric" 1.65 | grep -q "in metres: "
# The installed Python package (when the build made one): imported from the prefix alone, with the
# shipped configs found there, the same depth as geo_infer's.
py_dir=$(find "$T/prefix" -path '*-packages/geo/__init__.py' -printf '%h\n' | head -1)
if [ -n "$py_dir" ]; then
  python=$(sed -n 's/^GEO_PYTHON_EXECUTABLE_USED:[A-Z]*=//p' "$BUILD/CMakeCache.txt")
  (cd "$T" && PYTHONPATH="$(dirname "$py_dir")" "${python:-python3}" -c "
import geo, os, sys
assert geo.__file__.startswith('$T/prefix'), geo.__file__
assert os.environ['GEO_CONFIG_DIR'] == '$T/prefix/share/geo/configs', os.environ['GEO_CONFIG_DIR']
model = geo.Model.load('$T/model.pt')
for name in sorted(os.listdir('$T/frames')):
    stem = name[:-4]
    image = geo.io.read_image('$T/frames/' + name, size=(model.spec.height, model.spec.width))
    geo.io.write_depth_png('$T/py-' + stem + '.png', model.depth(image))
")
  for f in "$T"/frames/*.png; do
    name=$(basename "$f" .png)
    cmp "$T/infer/$name-depth.png" "$T/py-$name.png"
  done
  echo "the installed Python package: $n depth maps identical to geo_infer's"
fi
echo "depth_from_camera built against $T/prefix: $n depth maps identical to geo_infer's"
