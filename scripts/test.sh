#!/usr/bin/env bash
# Installs dependencies, builds, and runs every test (gtest + rostest through ctest).
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
export PATH="/usr/bin:$PATH"
bash "$ROOT/scripts/install_deps.sh"
bash "$ROOT/scripts/build.sh"
export MCFLOW_SHARED_DATA="${MCFLOW_SHARED_DATA:-$(cd "$ROOT/.." && pwd)/shared/data}"
cd "${MCFLOW_BUILD_DIR:-$ROOT/build}"
OMP_WAIT_POLICY=passive ctest --output-on-failure -j"$(nproc)"
