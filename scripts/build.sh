#!/usr/bin/env bash
# Configures and builds mc_flow (and its tests) into build/. Uses CUDA when nvcc is found.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BUILD="${MCFLOW_BUILD_DIR:-$ROOT/build}"
if [ -z "${CUDACXX:-}" ] && [ -x /usr/local/cuda/bin/nvcc ]; then export CUDACXX=/usr/local/cuda/bin/nvcc; fi
# Debian's ROS python modules live in /usr/lib/python3; a pyenv python3 on PATH cannot import them.
mkdir -p "$BUILD/devel/lib/python3/dist-packages"
cmake -S "$ROOT" -B "$BUILD" -DCMAKE_BUILD_TYPE=Release \
  -DPYTHON_EXECUTABLE=/usr/bin/python3 -DPython3_EXECUTABLE=/usr/bin/python3 \
  -DCATKIN_DEVEL_PREFIX="$BUILD/devel" -DCATKIN_ENABLE_TESTING=ON ${MCFLOW_CMAKE_FLAGS:-} >/dev/null
cmake --build "$BUILD" -j"$(nproc)"
cmake --build "$BUILD" --target tests -j"$(nproc)"
