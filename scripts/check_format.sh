#!/usr/bin/env bash
# Checks that every C++ and CUDA file git tracks is formatted as .clang-format says (clang-format 14, the Debian 12
# package that scripts/install_deps.sh installs). Run by ctest (test format.ClangFormat) and so by CI.
#   scripts/check_format.sh        report the files that differ (exit 1 if any)
#   scripts/check_format.sh --fix  format them in place
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
cd "$ROOT"
CLANG_FORMAT="${CLANG_FORMAT:-clang-format-14}"
command -v "$CLANG_FORMAT" >/dev/null || { echo "check_format.sh: $CLANG_FORMAT not found: run scripts/install_deps.sh" >&2; exit 2; }
mapfile -t files < <(git ls-files '*.cpp' '*.h' '*.cu' '*.cuh')
[ ${#files[@]} -gt 0 ] || { echo "check_format.sh: no tracked C++ files (not a git checkout?)" >&2; exit 2; }
if [ "${1:-}" = --fix ]; then
  "$CLANG_FORMAT" -i "${files[@]}"
  exit 0
fi
bad=()
for f in "${files[@]}"; do
  "$CLANG_FORMAT" --dry-run --Werror "$f" >/dev/null 2>&1 || bad+=("$f")
done
if [ ${#bad[@]} -gt 0 ]; then
  echo "check_format.sh: ${#bad[@]} of ${#files[@]} files are not formatted (scripts/check_format.sh --fix):" >&2
  printf '  %s\n' "${bad[@]}" >&2
  exit 1
fi
echo "check_format.sh: ${#files[@]} files formatted"
