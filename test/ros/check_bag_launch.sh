#!/bin/bash
# demo.launch as a user meets it with a recorded bag:
#  1. --ros-args: every argument documented, none but bag Required (mc_flow.launch: none);
#  2. a bag with only the three camera topics (no TF; depth 16UC1 in its own frame), given by a path
#     relative to the folder roslaunch starts in: it plays, and every output's frame_id is the rviz
#     config's default Fixed Frame, so rviz needs no transform; the launch ends without a process dying;
#  3. a relative path to no file: refused before anything starts, naming the resolved path;
#  4. a file the player cannot read: the demo ends with the reason and status 1, not a timeout.
# Usage: check_bag_launch.sh SOURCE_DIR DEVEL_DIR
set -uo pipefail
src=$1
devel=$2
export PATH="/usr/bin:$PATH"
set +u
# shellcheck disable=SC1091
source "$devel/setup.bash"
set -u
port=$((11400 + RANDOM % 500))
export ROS_MASTER_URI="http://localhost:$port"
work=$(mktemp -d /tmp/mc_flow_bag_launch.XXXXXX)
trap 'rm -rf "$work"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

# 1. documentation of the arguments
for launch in demo.launch mc_flow.launch; do
  dump=$(roslaunch mc_flow "$launch" --ros-args 2>&1) || fail "$launch --ros-args: $dump"
  echo "$dump" | grep -q "undocumented" && fail "$launch has undocumented arguments: $dump"
  required=$(echo "$dump" | awk '/^Required Arguments:/{r=1; next} /^Optional Arguments:/{r=0} r' | sed 's/:.*//' | tr -d ' ')
  expected=$([ "$launch" = demo.launch ] && echo bag || true)
  [ "$required" = "$expected" ] || fail "$launch: Required arguments '$required', expected '$expected'"
done
echo "ok   --ros-args: every argument documented; Required: bag only"

# 2. a bag of the three topics, relative path
fixed=$(sed -n 's/^ *Fixed Frame: *//p' "$src/rviz/mc_flow.rviz" | head -1)
[ -n "$fixed" ] || fail "no Fixed Frame in rviz/mc_flow.rviz"
mkdir -p "$work/bags"
"$devel/lib/mc_flow/make_synthetic_bag" "$work/bags/three.bag" --frames 5 --width 320 --height 240 --no-tf \
    --depth-encoding 16UC1 --depth-frame-id camera_depth_optical_frame >/dev/null || fail "make_synthetic_bag"
topics=$(rosbag info -y -k topics "$work/bags/three.bag" | grep -c "topic:")
[ "$topics" = 3 ] || fail "the bag has $topics topics, expected 3"
(cd "$work/bags" && roslaunch -p "$port" mc_flow demo.launch bag:=three.bag rate:=0.3 rviz:=false save_dir:=none \
    status_file:="$work/status" >"$work/launch.log" 2>&1) &
launch_pid=$!
"$src/test/ros/output_frames.py" /camera/mc_flow 90 >"$work/frames" 2>"$work/frames.err"
frames_rc=$?
wait "$launch_pid"
cat "$work/frames"
[ "$frames_rc" = 0 ] || { tail -20 "$work/launch.log"; fail "not every output arrived"; }
grep -q "^FRAME " "$work/frames" || fail "no output frames recorded"
while read -r _ name ids; do
  [ "$ids" = "$fixed" ] || fail "$name carries frame_id '$ids', not the rviz Fixed Frame '$fixed'"
done < <(grep "^FRAME " "$work/frames")
[ "$(cut -d' ' -f1 "$work/status" 2>/dev/null)" = 0 ] || { tail -20 "$work/launch.log"; fail "demo status: $(cat "$work/status" 2>/dev/null)"; }
# A demo that went well ends without roslaunch's red "REQUIRED process [...] has died!".
! grep -q "has died" "$work/launch.log" || { grep -B2 -A3 "has died" "$work/launch.log"; fail "a process died at the end of the demo"; }
echo "ok   bag:=three.bag relative to the launch folder; every output in '$fixed'; clean end"

# 3. a relative path to nothing
out=$(cd "$work" && timeout 60 roslaunch -p "$port" mc_flow demo.launch bag:=missing.bag rviz:=false 2>&1)
rc=$?
[ "$rc" != 0 ] && [ "$rc" != 124 ] || fail "bag:=missing.bag: exit $rc"
echo "$out" | grep -q "No such file or directory: '$work/missing.bag'" || fail "bag:=missing.bag: message does not name $work/missing.bag: $out"
echo "ok   bag:=missing.bag refused up front (exit $rc), naming $work/missing.bag"

# 4. a bag the player cannot read
echo "not a bag" >"$work/broken.bag"
start=$SECONDS
out=$(cd "$work" && timeout 120 roslaunch -p "$port" mc_flow demo.launch bag:=broken.bag rviz:=false save_dir:=none \
      status_file:="$work/status_broken" 2>&1)
[ $((SECONDS - start)) -lt 100 ] || fail "broken bag: the demo took $((SECONDS - start)) s"
grep -q "^1 .*ended without publishing" "$work/status_broken" 2>/dev/null || fail "broken bag: status '$(cat "$work/status_broken" 2>/dev/null)'; output: $(echo "$out" | tail -15)"
echo "$out" | grep -q "demo failed" || fail "broken bag: no 'demo failed' on the screen: $out"
echo "ok   a bag the player cannot read ends the demo in $((SECONDS - start)) s: $(cut -d' ' -f2- "$work/status_broken" | cut -c1-90)..."
