#!/usr/bin/env bash
# Builds the gtest unit tests with ASan+UBSan (-DMCFLOW_SANITIZE=ON, CPU only) in their own build folder and
# runs them through ctest; any finding aborts its test.
#   scripts/test_sanitized.sh           core, I/O (with the mcflow tool they run), ROS unit and bag tests
#   scripts/test_sanitized.sh core-io   core and I/O only, without ROS (what CI runs after the other tests)
# No rostests: a sanitized nodelet cannot be loaded into the uninstrumented nodelet manager.
# Build folder: $MCFLOW_SANITIZE_BUILD_DIR, or build-sanitize (all) / build-sanitize-core-io.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
scope="${1:-all}"
exclude='^$'
case "$scope" in
  all)     ros=ON;  targets="test_core test_io test_ros_units test_ros_bag"; labels='^(test_core|test_io|test_ros_units|test_ros_bag)$' ;;
  # The four real-pair accuracy tests (90 s under the sanitizers) are left to the full run; their loader
  # and halving code is also run by BenchRealCli on one pair.
  core-io) ros=OFF; targets="test_core test_io";                labels='^(test_core|test_io)$'
           exclude='^SharedData/RealPairs\.' ;;
  *) echo "usage: $0 [core-io]" >&2; exit 2 ;;
esac
BUILD="${MCFLOW_SANITIZE_BUILD_DIR:-$ROOT/build-sanitize$([ "$scope" = all ] || echo "-$scope")}"
mkdir -p "$BUILD/devel/lib/python3/dist-packages"
cmake -S "$ROOT" -B "$BUILD" --no-warn-unused-cli -DCMAKE_BUILD_TYPE=Release -DMCFLOW_SANITIZE=ON -DMCFLOW_WITH_CUDA=OFF \
  -DMCFLOW_WITH_ROS=$ros -DPYTHON_EXECUTABLE=/usr/bin/python3 -DPython3_EXECUTABLE=/usr/bin/python3 \
  -DCATKIN_DEVEL_PREFIX="$BUILD/devel" -DCATKIN_ENABLE_TESTING=ON >/dev/null
# shellcheck disable=SC2086
cmake --build "$BUILD" --target $targets -j"${MCFLOW_JOBS:-$(nproc)}"
export MCFLOW_SHARED_DATA="${MCFLOW_SHARED_DATA:-$(cd "$ROOT/.." && pwd)/shared/data}"
cd "$BUILD"
OMP_WAIT_POLICY=passive ctest --output-on-failure -L "$labels" -E "$exclude" -j"${MCFLOW_JOBS:-$(nproc)}"
