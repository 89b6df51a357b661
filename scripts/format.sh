#!/usr/bin/env bash
# Formats geo's C++ sources (src, apps, include, tests, python, examples) with .clang-format.
#   scripts/format.sh            rewrite the files that differ
#   scripts/format.sh --check    only list them; exit 1 when any differs (the test suite's
#                                Format.SourcesFollowClangFormat)
# The tree is formatted with clang-format 14 (Debian 12's package `clang-format`, which
# scripts/setup.sh installs); other versions format some constructs differently, so --check with
# another version (or none) says so and exits 77 (the test is then skipped), never 1.
set -euo pipefail
cd "$(dirname "$0")/.."
CHECK=0
case "${1:-}" in
  --check) CHECK=1 ;;
  "") ;;
  *) echo "usage: scripts/format.sh [--check]" >&2; exit 2 ;;
esac
FORMAT="${GEO_CLANG_FORMAT:-clang-format}"
if ! command -v "$FORMAT" >/dev/null; then
  echo "format: $FORMAT not found (Debian: apt-get install clang-format)" >&2
  exit 77
fi
version="$("$FORMAT" --version | sed -n 's/.*version \([0-9]*\).*/\1/p')"
if [ "$version" != 14 ]; then
  echo "format: $FORMAT is version ${version:-unknown}; the tree is formatted with clang-format 14 (set GEO_CLANG_FORMAT)" >&2
  [ "$CHECK" = 1 ] && exit 77
fi
if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  mapfile -t files < <(git ls-files -- 'src/*.cpp' 'src/*.h' 'apps/*.cpp' 'apps/*.h' 'include/*.h' 'tests/*.cpp' \
                                      'tests/*.h' 'python/*.cpp' 'python/*.h' 'examples/*.cpp')
else
  mapfile -t files < <(find src apps include tests python examples -name '*.cpp' -o -name '*.h' | sort)
fi
# One clang-format for all files (one process per file took 40 s where starting a process is dear):
# --dry-run names each file that would change.
present=()
for f in "${files[@]}"; do [ -f "$f" ] && present+=("$f"); done
report="$("$FORMAT" --style=file --dry-run "${present[@]}" 2>&1)" ||
  { printf '%s\n' "$report" | tail -n 20 >&2; echo "format: $FORMAT failed (above)" >&2; exit 2; }
mapfile -t differ < <(printf '%s\n' "$report" |
  sed -n 's/^\(.*\):[0-9]*:[0-9]*: warning: code should be clang-formatted.*/\1/p' | sort -u)
if [ "$CHECK" = 0 ] && ((${#differ[@]})); then "$FORMAT" --style=file -i "${differ[@]}"; fi
if [ "$CHECK" = 1 ]; then
  if ((${#differ[@]})); then
    printf 'format: %s differs from .clang-format (scripts/format.sh rewrites it)\n' "${differ[@]}" >&2
    exit 1
  fi
  echo "format: ${#files[@]} files follow .clang-format"
else
  echo "format: ${#differ[@]} of ${#files[@]} files rewritten"
fi
