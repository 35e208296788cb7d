#!/usr/bin/env bash
# Runs one fuzz target on a fresh seed corpus made by `mcflow synth` (docs/TESTING.md).
#   test/fuzz/run_fuzz.sh BUILD_DIR TARGET [libFuzzer options...]
# TARGET: colour_image depth_image depth_pfm flo camera_info config_file. Options go to libFuzzer, e.g.
# -runs=2000 (the ctest smoke run) or -max_total_time=300. New inputs go to a temporary corpus, removed at
# the end unless MCFLOW_FUZZ_CORPUS names a folder to keep them in. A crash or sanitizer report fails the
# run and leaves its input as crash-* / leak-* / timeout-* in MCFLOW_FUZZ_ARTIFACTS (default: BUILD_DIR/fuzz-findings).
set -euo pipefail
[ $# -ge 2 ] || { sed -n 2,7p "$0" >&2; exit 2; }
build=$(cd "$1" && pwd); target=$2; shift 2
work=$(mktemp -d "${TMPDIR:-/tmp}/mcflow_fuzz_run.XXXXXX")
trap 'rm -rf "$work"' EXIT
# Two small scenes (40x30): seeds of a few KB keep each execution fast.
for variant in 0 1; do
  "$build/mcflow" synth --out "$work/synth$variant" --variant $variant --width 40 --height 30 >/dev/null
  "$build/fuzz_make_seeds" "$work/synth$variant" "$work/seeds$variant"
done
corpus=${MCFLOW_FUZZ_CORPUS:-$work/corpus}
artifacts=${MCFLOW_FUZZ_ARTIFACTS:-$build/fuzz-findings}
mkdir -p "$corpus" "$artifacts"
# OpenCV prints a warning for every undecodable image; they say nothing here.
export OPENCV_LOG_LEVEL=ERROR
export ASAN_OPTIONS="${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
# Not exec: the EXIT trap must still remove the work folder.
"$build/fuzz_$target" -artifact_prefix="$artifacts/${target}-" -print_final_stats=1 "$@" \
  "$corpus" "$work/seeds0/$target" "$work/seeds1/$target"
