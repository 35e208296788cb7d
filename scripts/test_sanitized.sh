#!/usr/bin/env bash
# Builds the gtest unit tests with ASan+UBSan (-DMCFLOW_SANITIZE=ON, CPU only) in their own build folder and
# runs them through ctest; any finding aborts its test.
#   scripts/test_sanitized.sh           core, I/O (with the mcflow tool they run), ROS unit and bag tests
#   scripts/test_sanitized.sh core-io   core and I/O only, without ROS (what CI runs after the other tests), then the
#                                       fuzz smoke: each libFuzzer target for a fixed count of inputs (cmake/fuzz.cmake)
# core-io builds with clang-14 and -DMCFLOW_FUZZ=ON, so that one sanitized build serves the tests and the fuzz
# targets (MCFLOW_SANITIZE_FUZZ=0: gcc and no fuzzing, as before).
# No rostests: a sanitized nodelet cannot be loaded into the uninstrumented nodelet manager.
# Build folder: $MCFLOW_SANITIZE_BUILD_DIR, or build-sanitize (all) / build-sanitize-core-io-fuzz (gcc: build-sanitize-core-io).
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
scope="${1:-all}"
exclude='^$'
fuzz=()
case "$scope" in
  all)     ros=ON;  targets="test_core test_io test_ros_units test_ros_bag"; labels='^(test_core|test_io|test_ros_units|test_ros_bag)$' ;;
  # The four real-pair accuracy tests (90 s under the sanitizers) are left to the full run; their loader
  # and halving code is also run by BenchRealCli on one pair. So are the two longest stream tests (the TUM office
  # excerpt warm and cold, parts moving alike for a moment: 330 s and 220 s of the sanitized run's 1380 CPU-seconds);
  # the other stream tests run the same code sanitized.
  core-io) ros=OFF; targets="test_core test_io";                labels='^(test_core|test_io)$'
           exclude='^(SharedData/RealPairs\.|OneRigidThing\.TheTumOfficeIsOneSegmentWarmAndCold$|SolverStream\.PartsThatMoveAlikeForAMomentKeepTheirSegments$)'
           if [ "${MCFLOW_SANITIZE_FUZZ:-1}" != 0 ]; then
             fuzz=(-DCMAKE_C_COMPILER=clang-14 -DCMAKE_CXX_COMPILER=clang++-14 -DMCFLOW_FUZZ=ON)
             targets="$targets fuzz_targets"; labels='^(test_core|test_io|fuzz)$'
           fi ;;
  *) echo "usage: $0 [core-io]" >&2; exit 2 ;;
esac
# The clang build gets its own folder: a compiler change cannot reuse a gcc build's cache.
BUILD="${MCFLOW_SANITIZE_BUILD_DIR:-$ROOT/build-sanitize$([ "$scope" = all ] || echo "-$scope")$([ ${#fuzz[@]} = 0 ] || echo -fuzz)}"
mkdir -p "$BUILD/devel/lib/python3/dist-packages"
cmake -S "$ROOT" -B "$BUILD" --no-warn-unused-cli -DCMAKE_BUILD_TYPE=Release -DMCFLOW_SANITIZE=ON -DMCFLOW_WITH_CUDA=OFF \
  -DMCFLOW_WITH_ROS=$ros -DPYTHON_EXECUTABLE=/usr/bin/python3 -DPython3_EXECUTABLE=/usr/bin/python3 \
  -DCATKIN_DEVEL_PREFIX="$BUILD/devel" -DCATKIN_ENABLE_TESTING=ON "${fuzz[@]}" >/dev/null
# shellcheck disable=SC2086
cmake --build "$BUILD" --target $targets -j"${MCFLOW_JOBS:-$(nproc)}"
export MCFLOW_SHARED_DATA="${MCFLOW_SHARED_DATA:-$(cd "$ROOT/.." && pwd)/shared/data}"
cd "$BUILD"
OMP_WAIT_POLICY=passive ctest --output-on-failure -L "$labels" -E "$exclude" -j"${MCFLOW_JOBS:-$(nproc)}"
