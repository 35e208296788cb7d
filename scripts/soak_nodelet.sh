#!/bin/bash
# Soak benchmark of the nodelet on the CPU: a synthetic bag's frames published into mc_flow.launch (its own
# manager, the package's launch file) over and over until PAIRS pairs are solved, with a table of the
# manager's resident memory and the nodelet's counters every SAMPLE_EVERY pairs (scripts/soak_nodelet.py).
# Not a test: 10,000 pairs take about 12 minutes (one solver thread, 160x120, lockstep); a short run such
# as `scripts/soak_nodelet.sh 300` checks the setup.
#
# Usage: scripts/soak_nodelet.sh [PAIRS (10000)] [BUILD_DIR (build)]
# Environment:
#   SAMPLE_EVERY (100)   pairs per table row        WARMUP (200)  pairs before the memory fit
#   WIDTH x HEIGHT (320 x 240) of the bag, DOWNSAMPLE (2): processed at 160x120
#   FRAMES (20)          frames in the bag (played forwards and backwards)
#   RATE (0)             frames per second; 0: lockstep (each frame when the previous pair came out)
#   THREADS (1)          the solver's OpenMP threads (the `threads` parameter; 0: all cores)
#   MAX_GROWTH (2.0)     MB per 1000 pairs after the warm-up above which the run fails (exit 2)
#   MCFLOW_SOAK_PORT     ROS master port (a free one at random)
# Output: the table on stdout; the nodelet's log in the temporary folder it names when the run fails.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
pairs=${1:-10000}
build=$(cd "${2:-$root/build}" && pwd)
export PATH="/usr/bin:$PATH"  # Debian's ROS python tools, not a pyenv python3
set +u
# shellcheck disable=SC1091
source "$build/devel/setup.bash"
set -u
port=${MCFLOW_SOAK_PORT:-$((12400 + RANDOM % 500))}
export ROS_MASTER_URI="http://localhost:$port"
# Idle OpenMP threads must not spin between pairs (docs/PERFORMANCE.md): they would take the publisher's core.
export OMP_WAIT_POLICY=passive

work=$(mktemp -d /tmp/mc_flow_soak.XXXXXX)
master_pid="" launch_pid="" keep=0
cleanup() {
  if [ -n "$launch_pid" ]; then kill -INT "$launch_pid" 2>/dev/null || true; wait "$launch_pid" 2>/dev/null || true; fi
  if [ -n "$master_pid" ]; then kill -INT "$master_pid" 2>/dev/null || true; wait "$master_pid" 2>/dev/null || true; fi
  if [ "$keep" = 1 ]; then echo "soak: logs kept in $work" >&2; else rm -rf "$work"; fi
}
trap cleanup EXIT

bag="$work/soak.bag"
"$build/devel/lib/mc_flow/make_synthetic_bag" "$bag" --frames "${FRAMES:-20}" --width "${WIDTH:-320}" \
    --height "${HEIGHT:-240}" --no-tf >/dev/null
printf 'backend: cpu\nthreads: %s\n' "${THREADS:-1}" >"$work/solver.yaml"

roscore -p "$port" >"$work/master.log" 2>&1 &
master_pid=$!
for _ in $(seq 1 60); do rosparam list >/dev/null 2>&1 && break; sleep 0.5; done
roslaunch -p "$port" mc_flow mc_flow.launch camera:=camera downsample:="${DOWNSAMPLE:-2}" \
    params_file:="$work/solver.yaml" output:=log >"$work/launch.log" 2>&1 &
launch_pid=$!
for _ in $(seq 1 120); do rosnode list 2>/dev/null | grep -qx /camera/mc_flow_manager && break; sleep 0.5; done

status=0
python3 "$root/scripts/soak_nodelet.py" --bag "$bag" --pairs "$pairs" --sample-every "${SAMPLE_EVERY:-100}" \
    --warmup "${WARMUP:-200}" --rate "${RATE:-0}" --max-growth "${MAX_GROWTH:-2.0}" || status=$?
if [ "$status" != 0 ]; then
  keep=1
  cp "$HOME"/.ros/log/latest/camera-mc_flow_manager-*.log "$work/" 2>/dev/null || true
fi
exit "$status"
