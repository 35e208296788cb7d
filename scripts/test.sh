#!/usr/bin/env bash
# Installs dependencies, builds, and runs every test (gtest + rostest through ctest), then the core and I/O
# tests again under ASan+UBSan and the fuzz smoke (scripts/test_sanitized.sh core-io: one clang build,
# build-sanitize-core-io-fuzz).
#   MCFLOW_SANITIZE=1 bash scripts/test.sh   only the sanitized tests: core, I/O and ROS unit tests
#   MCFLOW_SANITIZE=0 bash scripts/test.sh   no sanitized tests
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
export PATH="/usr/bin:$PATH"
# clang for the sanitized build that also runs the fuzz smoke, unless the sanitized tests are off.
bash "$ROOT/scripts/install_deps.sh" $([ "${MCFLOW_SANITIZE:-}" = 0 ] || echo --fuzz)
export MCFLOW_SHARED_DATA="${MCFLOW_SHARED_DATA:-$(cd "$ROOT/.." && pwd)/shared/data}"
if [ "${MCFLOW_SANITIZE:-}" = 1 ]; then
  exec bash "$ROOT/scripts/test_sanitized.sh"
fi
bash "$ROOT/scripts/build.sh"
(cd "${MCFLOW_BUILD_DIR:-$ROOT/build}" && OMP_WAIT_POLICY=passive ctest --output-on-failure -j"$(nproc)")
if [ "${MCFLOW_SANITIZE:-}" != 0 ]; then
  bash "$ROOT/scripts/test_sanitized.sh" core-io
fi
