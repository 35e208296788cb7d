#!/bin/bash
# End-to-end demo without a camera: writes a synthetic RGB-D bag (moving boxes and an articulated arm),
# plays it into the MC-Flow nodelet headless, prints one summary line per pair (segments, their speeds,
# solve time) and saves the pictures. Exits by itself when the bag has been processed.
#
# Usage: scripts/run_demo.sh [BUILD_DIR (build_ros)] [OUTPUT_DIR (/tmp/mc_flow_demo)]
# Environment: FRAMES (20) frames in the bag; RATE (0.2) playback speed factor of the 10 Hz bag: pick it
# so that one frame arrives per solve (frames arriving during a solve are dropped and counted);
# MCFLOW_DEMO_PORT (11345) port of the demo's own ROS master; RVIZ (false).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=$(cd "${1:-$root/build_ros}" && pwd)
out=${2:-/tmp/mc_flow_demo}
frames=${FRAMES:-20}
rate=${RATE:-0.2}
port=${MCFLOW_DEMO_PORT:-11345}

# The ROS setup scripts read unset variables: source them without -u.
set +u
# shellcheck disable=SC1091
source "$build/devel/setup.bash"
set -u
export ROS_MASTER_URI="http://localhost:$port"
mkdir -p "$out"
rm -f "$out"/pictures/*.png 2>/dev/null || true

bag="$out/mc_flow_synthetic.bag"
"$build/devel/lib/mc_flow/make_synthetic_bag" "$bag" --frames "$frames" --rate 10
echo "playing $bag at rate $rate into the nodelet (pictures: $out/pictures)"
# demo_monitor ends roslaunch, which then exits 0 even on failure: the monitor's status file says.
status="$out/demo_status"
rm -f "$status"
roslaunch -p "$port" mc_flow demo.launch bag:="$bag" rate:="$rate" save_dir:="$out/pictures" \
    rviz:="${RVIZ:-false}" status_file:="$status"
if [ ! -s "$status" ]; then
  echo "run_demo.sh: the demo ended without a result (roslaunch refused to start, or was interrupted)" >&2
  exit 1
fi
read -r code reason < "$status" || true
if [ "$code" != "0" ]; then
  echo "run_demo.sh: demo failed: $reason" >&2
  exit 1
fi
