#!/usr/bin/env bash
# geo against PyTorch at its best, on this CPU, side by side (benchmarks/vs_pytorch.py says what
# is run): PyTorch 1.13 (Debian 12's python3-torch) and PyTorch 2.6 (Debian 13's, in the root that
# scripts/debian13.sh makes), eager / bf16 autocast / channels-last / torch.compile, glibc's
# allocator and jemalloc; geo on LibTorch 1.13 and 2.6, fp32 and bf16. DepthNet inference at batch
# 1 and a stage-1 training step at batch 4; each variant in its own process, so that one that
# crashes is recorded and the table goes on. Not part of CI: it takes about an hour of a quiet
# 2-core machine and installs packages (python3-torch, libjemalloc2; in the Debian 13 root also
# python3-dev and python3-setuptools, which torch.compile's C++ backend needs).
#   benchmarks/vs_pytorch.sh [vs_pytorch.py options: --rounds 2 --platforms d12 --rows depth ...]
# Environment: GEO_BUILD_DIR (default build), GEO_DEBIAN13_ROOT (as scripts/debian13.sh).
# Writes bench-vs-pytorch/table.md (and runs.jsonl, every run as a JSON line) and prints the table.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD="${GEO_BUILD_DIR:-build}"
as_root() { if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi; }

missing=()
/usr/bin/python3 -c 'import torch' 2>/dev/null || missing+=(python3-torch)
[ -e /usr/lib/x86_64-linux-gnu/libjemalloc.so.2 ] || missing+=(libjemalloc2)
if ((${#missing[@]})); then
  echo "vs_pytorch: installing ${missing[*]}"
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}" >/dev/null
fi
echo "vs_pytorch: geo_bench on Debian 12 (LibTorch 1.13)"
GEO_BUILD_DIR="$BUILD" GEO_TARGETS=geo_bench scripts/setup.sh >/dev/null
if [[ " $* " != *" --platforms d12 "* ]]; then
  echo "vs_pytorch: geo_bench and PyTorch's compiler needs in the Debian 13 root (LibTorch 2.6)"
  GEO_TARGETS=geo_bench GEO_OPENCV=0 scripts/debian13.sh bash -c \
    'DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends python3-dev python3-setuptools libjemalloc2 >/dev/null && scripts/setup.sh >/dev/null'
fi
exec /usr/bin/python3 benchmarks/vs_pytorch.py --build "$BUILD" "$@"
