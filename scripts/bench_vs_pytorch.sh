#!/bin/sh
# geo's CPU inference side by side with GeoNet's ResNet-50 DepthNet in eager PyTorch
# (scripts/pytorch_reference.py: the same network, same parameter count, as a PyTorch user runs it),
# in interleaved rounds on this machine, with the ratios. On Debian 12, python3-torch is the same
# LibTorch 1.13 that geo builds on, so the comparison is of the two programs, not of two LibTorch
# builds. Not part of CI (it needs PyTorch and minutes of quiet CPU).
#
#   scripts/bench_vs_pytorch.sh                  (GEO_BUILD_DIR=build, THREADS=nproc, ROUNDS=2, ITERS=9)
#   GEO_PYTORCH_INSTALL=1 scripts/bench_vs_pytorch.sh   installs python3-torch first (apt, root)
# Writes bench-vs-pytorch/{pytorch,geo}-<round>.json and prints the table.
set -eu
cd "$(dirname "$0")/.."
BUILD=${GEO_BUILD_DIR:-build}
THREADS=${THREADS:-$(nproc)}
ROUNDS=${ROUNDS:-2}
ITERS=${ITERS:-9}
OUT=${OUT:-bench-vs-pytorch}
PY=${GEO_PYTHON:-/usr/bin/python3}

if [ "${GEO_PYTORCH_INSTALL:-0}" = 1 ]; then
  DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends python3-torch
fi
if ! "$PY" -c 'import torch' 2>/dev/null; then
  echo "bench_vs_pytorch: $PY cannot import torch; on Debian: apt-get install python3-torch" \
       "(or GEO_PYTORCH_INSTALL=1), elsewhere set GEO_PYTHON to a python with PyTorch" >&2
  exit 2
fi
if [ ! -x "$BUILD/apps/geo_bench" ]; then
  echo "bench_vs_pytorch: $BUILD/apps/geo_bench not built (scripts/setup.sh)" >&2
  exit 2
fi
mkdir -p "$OUT"
r=1
while [ "$r" -le "$ROUNDS" ]; do
  echo "round $r/$ROUNDS: PyTorch" >&2
  "$PY" scripts/pytorch_reference.py --threads "$THREADS" --iters "$ITERS" > "$OUT/pytorch-$r.json"
  echo "round $r/$ROUNDS: geo" >&2
  "$BUILD/apps/geo_bench" --fr both --no-train --no-comm --batch 1 --precision bf16 --threads "$THREADS" \
    --warmup 5 --iters "$ITERS" --json "$OUT/geo-$r.json" > "$OUT/geo-$r.log" 2>&1
  r=$((r + 1))
done

"$PY" - "$OUT" "$ROUNDS" "$THREADS" <<'PY'
import json, sys
out, rounds, threads = sys.argv[1], int(sys.argv[2]), sys.argv[3]
flags = open("/proc/cpuinfo").read().split("flags\t\t: ")[1].split("\n")[0].split()
shown = [f for f in ("avx2", "avx512f", "avx512_bf16", "amx_bf16") if f in flags]
model = [l.split(": ", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")][0]
print(f"CPU: {model}, {threads} threads, flags: {' '.join(shown)}")
for r in range(1, rounds + 1):
    py = json.load(open(f"{out}/pytorch-{r}.json"))
    geo = json.load(open(f"{out}/geo-{r}.json"))
    params = {(x["what"], x["fr"]): x["parameters"] for x in geo["rows"] if x["section"] == "params"}
    same = params.get(("DepthNet", "off")) == py["params"]
    print(f"round {r}: PyTorch {py['torch']} DepthNet {py['median_ms']:.1f} ms "
          f"({py['params']} parameters, {'the same as' if same else 'DIFFERENT FROM'} geo's DepthNet with FR off)")
    for x in geo["rows"]:
        if x["section"] != "infer" or x["batch"] != 1 or not x["what"].split()[0] in ("DepthNet", "Model::depth"):
            continue
        print(f"  geo {x['what']:<18} FR {x['fr']:<3} {x['ms']:8.1f} ms  ratio to PyTorch {x['ms'] / py['median_ms']:.2f}")
    if not same:
        sys.exit("the PyTorch reference and geo's DepthNet differ in parameter count: not the same network")
PY
