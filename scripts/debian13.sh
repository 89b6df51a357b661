#!/usr/bin/env bash
# Runs one of geo's scripts on Debian 13 (trixie: LibTorch/PyTorch 2.6, Clang 19, GCC 14) from a Debian 12
# machine: makes (or reuses) a Debian 13 root with mmdebstrap from the host's own Debian mirror,
# copies the checkout into it and runs the script there.
#   scripts/debian13.sh scripts/test.sh            the test suite on LibTorch 2.6
#   scripts/debian13.sh scripts/demo.sh            the demo (its out/ lands in out/debian13/)
#   GEO_OPENCV=0 scripts/debian13.sh scripts/test.sh   without OpenCV, as on a PyTorch GPU image
#   scripts/debian13.sh bash                       a shell in the root, in the checkout's copy
#   GEO_DEBIAN13_CUDA=1 GEO_OPENCV=0 scripts/debian13.sh scripts/test.sh
#                      the same on Debian's CUDA build of LibTorch 2.6 (contrib: CUDA 12.4, NCCL),
#                      with nvcc; no GPU needed: the CUDA code is compiled, the CUDA tests skip
# Environment:
#   GEO_DEBIAN13_ROOT  where the root lives (default: ~/.cache/geo/debian13; ~1.7 GB, made in ~3-6
#                      minutes, reused afterwards; delete the folder to make it anew)
#   GEO_DEBIAN13_CUDA  1: the CUDA root (see above)
#   GEO_DEBIAN13_CUDA_ROOT  where that one lives (default: ~/.cache/geo/debian13-cuda; ~8 GB, ~3 min)
#   GEO_* variables are passed on to the script inside.
# The root sees the checkout as /src/geo (a copy: build folders inside it are kept between runs, so
# rebuilds are incremental), ../shared as /src/shared (read-only) and out/debian13 as /src/geo/out.
# Mounts live in a private mount namespace: they are gone when the command ends, however it ends.
# Needs root (or sudo), unshare and chroot (util-linux and coreutils: on every Debian).
set -euo pipefail
cd "$(dirname "$0")/.."
CHECKOUT="$(pwd)"
(($#)) || { sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//'; exit 2; }

if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "geo debian13: needs root or sudo (mmdebstrap, chroot, mounts)" >&2; exit 1; }
  exec sudo --preserve-env "$0" "$@"
fi

CUDA="${GEO_DEBIAN13_CUDA:-0}"
[ "$CUDA" = 0 ] || [ "$CUDA" = 1 ] || { echo "geo debian13: GEO_DEBIAN13_CUDA must be 0 or 1, not '$CUDA'" >&2; exit 1; }
if [ "$CUDA" = 1 ]; then NAME=debian13-cuda ROOT="${GEO_DEBIAN13_CUDA_ROOT:-${HOME:-/root}/.cache/geo/debian13-cuda}"
else NAME=debian13 ROOT="${GEO_DEBIAN13_ROOT:-${HOME:-/root}/.cache/geo/debian13}"; fi
# A root made for the other flavour (a folder named for both) is refused, not used.
if [ -f "$ROOT/.geo-root-complete" ] && [ -s "$ROOT/.geo-root-complete" ] && [ "$(cat "$ROOT/.geo-root-complete")" != "$NAME" ]; then
  echo "geo debian13: $ROOT holds the $(cat "$ROOT/.geo-root-complete") root, not $NAME: give each its own folder (GEO_DEBIAN13_ROOT, GEO_DEBIAN13_CUDA_ROOT)" >&2
  exit 1
fi
# Debian 13 packages the root starts with; scripts/setup.sh inside adds what it needs.
COMMON=python3-yaml,python3-numpy,python3-dev,pybind11-dev,python3-pytest,python3-onnx,libopenblas0-pthread,g++,clang,cmake,make,ninja-build,ccache,libyaml-cpp-dev,libcli11-dev,libspdlog-dev,libgtest-dev,libgmock-dev
COMPONENTS=main
if [ "$CUDA" = 1 ]; then
  # contrib: the CUDA build of LibTorch (with its Gloo and Python packages); non-free: the CUDA
  # toolkit (nvcc, which LibTorch's CMake config requires), its libraries and NCCL's headers.
  PACKAGES=python3-torch-cuda,libtorch-cuda-dev,libgloo-cuda-dev,libnccl-dev,nvidia-cuda-toolkit,$COMMON
  COMPONENTS=main,contrib,non-free
else
  PACKAGES=python3-torch,libtorch-dev,libgloo-dev,$COMMON
fi

# The host's Debian mirror (its main archive, as apt uses it): never written into the repository.
host_mirror() {
  local codename
  codename="$(. /etc/os-release && echo "${VERSION_CODENAME:-}")"
  apt-cache policy 2>/dev/null |
    awk -v c="$codename/main" '$3 == c && $2 ~ /^https?:\/\// { print $2; exit }'
}

if [ ! -x "$ROOT/usr/bin/g++" ] || [ ! -f "$ROOT/.geo-root-complete" ]; then
  MIRROR="${GEO_DEBIAN_MIRROR:-$(host_mirror)}"
  [ -n "$MIRROR" ] || { echo "geo debian13: no Debian mirror found in the host's apt sources (apt-cache policy); set GEO_DEBIAN_MIRROR" >&2; exit 1; }
  if ! command -v mmdebstrap >/dev/null; then
    echo "geo debian13: installing mmdebstrap"
    apt-get update -q >/dev/null
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends mmdebstrap >/dev/null
  fi
  echo "geo debian13: making a Debian 13 root ($NAME) in $ROOT from $MIRROR (a few minutes, several GB)"
  mkdir -p "$(dirname "$ROOT")"
  rm -rf "$ROOT.partial"
  EXTRA=()
  if [ "$CUDA" = 1 ]; then
    # Debian's nvidia-cudnn is an installer: its postinst downloads cuDNN from NVIDIA, which an
    # offline machine (or one that sees only the Debian mirror) cannot. LibTorch's package needs it
    # only as libcudnn.so.9 for the dynamic linker; cuDNN's code runs only on a GPU. A stand-in
    # package satisfies the dependency and a stub libcudnn.so.9 (below) the linker: geo compiles and
    # links against the CUDA LibTorch and runs its tests on the CPU. On a machine with a GPU, use a
    # real cuDNN (scripts/gpu_check.sh uses PyTorch's wheels, which bring theirs).
    # dpkg runs inside the root and apt outside: the package lies at the same path in both.
    STANDIN="$(mktemp -d /tmp/geo-cudnn-standin.XXXXXX)"
    mkdir -p "$STANDIN/pkg/DEBIAN"
    cat > "$STANDIN/pkg/DEBIAN/control" <<'CONTROL'
Package: nvidia-cudnn
Version: 9.0.0.312~cuda12+geo1
Architecture: amd64
Maintainer: geo <geo@localhost>
Provides: libcudnn.so.9
Section: contrib/libs
Priority: optional
Description: stand-in for the cuDNN installer in geo's CUDA compile root
 No cuDNN: scripts/debian13.sh adds a stub libcudnn.so.9 so that programs link against
 Debian's CUDA LibTorch and run on the CPU. Not for use with a GPU.
CONTROL
    dpkg-deb --build "$STANDIN/pkg" "$STANDIN/nvidia-cudnn-standin.deb" >/dev/null
    EXTRA=(--include="$STANDIN/nvidia-cudnn-standin.deb"
           --setup-hook="mkdir -p \"\$1$STANDIN\" && cp '$STANDIN/nvidia-cudnn-standin.deb' \"\$1$STANDIN/\""
           --customize-hook="rm -rf \"\$1$STANDIN\"")
  fi
  mmdebstrap --variant=apt --components="$COMPONENTS" --include="$PACKAGES" "${EXTRA[@]}" trixie "$ROOT.partial" "$MIRROR"
  if [ "$CUDA" = 1 ]; then
    rm -rf "$STANDIN"
    # The stub: every cuDNN function that LibTorch's libraries and its Python module name
    # (versioned libcudnn.so.9, as cuDNN's), none of which runs without a GPU. /usr/local/lib is on
    # the loader's and the linker's path.
    chroot "$ROOT.partial" /bin/bash -euo pipefail -c '
      syms=$({ find /usr/lib/x86_64-linux-gnu /usr/lib/python3/dist-packages/torch -name "*.so*" -type f \
                 \( -name "libtorch*" -o -name "libc10*" -o -name "libcaffe2*" -o -name "_C*" \) 2>/dev/null || true; } |
             xargs -r nm -D --undefined-only 2>/dev/null |
             awk "\$2 ~ /^cudnn.*@libcudnn.so.9\$/ { sub(/@.*/, \"\", \$2); print \$2 }" | sort -u)
      [ -n "$syms" ] || { echo "geo debian13: no cuDNN functions named by LibTorch" >&2; exit 1; }
      cd /tmp
      { echo "/* stub: geo compile root, no cuDNN */"; for s in $syms; do echo "int $s(void) { return 1; }"; done; } > cudnn_stub.c
      echo "libcudnn.so.9 { global: *; };" > cudnn_stub.map
      gcc -shared -fPIC -o /usr/local/lib/libcudnn.so.9 -Wl,-soname,libcudnn.so.9 -Wl,--version-script=cudnn_stub.map cudnn_stub.c
      rm cudnn_stub.c cudnn_stub.map
      ldconfig
      echo "geo debian13: stub libcudnn.so.9 with $(echo "$syms" | wc -w) functions"'
  fi
  echo "$NAME" > "$ROOT.partial/.geo-root-complete"
  rm -rf "$ROOT"
  mv "$ROOT.partial" "$ROOT"
fi

# The checkout's files (tracked and untracked-but-not-ignored) replace the previous copy; the
# copy's build folders and ccache stay. Only files whose content changed are written (and so get
# the current time): an object file built from an older copy is then never newer than its source,
# whatever the times of the checkout's files.
DEST="$ROOT/src/geo"
STAGE="$ROOT/src/.geo-incoming"
rm -rf "$STAGE"
mkdir -p "$DEST" "$STAGE" "$ROOT/src/shared" "$CHECKOUT/out/debian13"
if git -C "$CHECKOUT" rev-parse --git-dir >/dev/null 2>&1; then
  git -C "$CHECKOUT" ls-files -z --cached --others --exclude-standard |
    (cd "$CHECKOUT" && tar --null -T - -cf - 2>/dev/null) | tar -xf - -C "$STAGE"
else
  tar --exclude=./build --exclude='./build-*' --exclude=./out -cf - -C "$CHECKOUT" . | tar -xf - -C "$STAGE"
fi
(cd "$DEST" && find . \( -path ./out -o -path ./build -o -path './build-*' \) -prune -o \( -type f -o -type l \) -print0) |
  while IFS= read -r -d '' f; do [ -e "$STAGE/$f" ] || [ -L "$STAGE/$f" ] || rm -f "$DEST/$f"; done
(cd "$STAGE" && find . \( -type f -o -type l \) -print0) |
  while IFS= read -r -d '' f; do
    if [ -L "$STAGE/$f" ] || ! cmp -s "$STAGE/$f" "$DEST/$f"; then
      mkdir -p "$(dirname "$DEST/$f")"
      rm -f "$DEST/$f"
      cp -P --preserve=mode "$STAGE/$f" "$DEST/$f"
    fi
  done
rm -rf "$STAGE"
mkdir -p "$DEST/out"

ENV=(HOME=/root PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8 TERM="${TERM:-dumb}")
while IFS='=' read -r name _; do
  [[ "$name" == GEO_* && "$name" != GEO_DEBIAN13_ROOT ]] && ENV+=("$name=${!name}")
done < <(env)

SHARED=""
[ -d "$CHECKOUT/../shared" ] && SHARED="$(cd "$CHECKOUT/../shared" && pwd)"
echo "geo debian13: running '$*' in $ROOT (Debian $(cat "$ROOT/etc/debian_version"))"
# A private mount namespace: the kernel drops every mount below when the last process in it ends.
exec unshare --mount --propagation private -- /bin/bash -euo pipefail -c '
  root="$1" shared="$2" out="$3"; shift 3
  mount -t proc proc "$root/proc"
  mount --rbind /sys "$root/sys"
  mount --rbind /dev "$root/dev"
  [ -n "$shared" ] && mount --bind -o ro "$shared" "$root/src/shared"
  mount --bind "$out" "$root/src/geo/out"
  cp -L /etc/resolv.conf "$root/etc/resolv.conf" 2>/dev/null || true
  exec chroot "$root" /usr/bin/env -i "$@"
' geo-debian13 "$ROOT" "$SHARED" "$CHECKOUT/out/debian13" "${ENV[@]}" /bin/bash -c 'cd /src/geo && exec "$@"' geo "$@"
