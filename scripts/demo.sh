#!/usr/bin/env bash
# The main job on an embedded default (no camera, no downloads): installs dependencies, builds, then
#  1. `mcflow demo`: renders a synthetic RGB-D pair, solves it, writes every output + pictures to out/demo;
#  2. the ROS nodelet end to end, headless: a synthetic bag (moving boxes, an articulated arm) played into
#     the nodelet, one summary line per pair, pictures in out/ros_demo/pictures.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BUILD="${MCFLOW_BUILD_DIR:-$ROOT/build}"
OUT="${MCFLOW_DEMO_OUT:-$ROOT/out}"
export PATH="/usr/bin:$PATH"
export OMP_WAIT_POLICY=passive  # do not spin idle OpenMP threads next to the camera driver / ROS

bash "$ROOT/scripts/install_deps.sh"
bash "$ROOT/scripts/build.sh"

MCFLOW="$BUILD/devel/lib/mc_flow/mcflow"
[ -x "$MCFLOW" ] || MCFLOW="$BUILD/mcflow"
echo "=== 1/2 mcflow demo -> $OUT/demo"
"$MCFLOW" demo --out "$OUT/demo"

if [ -x "$BUILD/devel/lib/mc_flow/make_synthetic_bag" ]; then
  echo "=== 2/2 ROS nodelet on a synthetic bag -> $OUT/ros_demo"
  bash "$ROOT/scripts/run_demo.sh" "$BUILD" "$OUT/ros_demo"
else
  echo "=== 2/2 skipped: the ROS nodelet was not built (catkin not found)"
fi
echo "pictures: $OUT/demo/overview.png, $OUT/ros_demo/pictures/"
