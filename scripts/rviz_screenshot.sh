#!/bin/bash
# Writes docs/rviz.png the way a user sees it: a synthetic bag with only the three camera topics (no TF)
# played through demo.launch into the nodelet, rviz with the package's own config and its default Fixed
# Frame (fixed_frame:=auto), rendered under Xvfb, and a screenshot of the whole screen once the bag has
# been played and solved.
#
# FIXED_FRAME=camera_link (any frame but auto) plays the bag with its /tf_static (camera_link -> optical frame)
# instead and starts rviz in that frame: the view that start_rviz.py picks for a body frame.
#
# Usage: scripts/rviz_screenshot.sh [BUILD_DIR (build)] [OUTPUT_PNG (docs/rviz.png)]
# Environment: FRAMES (10), RATE (0.2), SETTLE (8 s), FIXED_FRAME (auto), MCFLOW_SCREENSHOT_PORT (11346),
# MCFLOW_SCREENSHOT_DISPLAY (:97).
# Needs rviz, Xvfb and ImageMagick's `import` (scripts/install_deps.sh installs them).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=$(cd "${1:-$root/build}" && pwd)
png=${2:-$root/docs/rviz.png}
frames=${FRAMES:-10}
rate=${RATE:-0.2}
port=${MCFLOW_SCREENSHOT_PORT:-11346}
display=${MCFLOW_SCREENSHOT_DISPLAY:-:97}
for tool in rviz Xvfb import; do
  command -v "$tool" >/dev/null || { echo "rviz_screenshot.sh: $tool not found: run scripts/install_deps.sh" >&2; exit 1; }
done

set +u
# shellcheck disable=SC1091
source "$build/devel/setup.bash"
set -u
export ROS_MASTER_URI="http://localhost:$port"
work=$(mktemp -d /tmp/mc_flow_screenshot.XXXXXX)
fixed_frame=${FIXED_FRAME:-auto}
if [ "$fixed_frame" = auto ]; then
  bag="$work/three_topics.bag"
  "$build/devel/lib/mc_flow/make_synthetic_bag" "$bag" --frames "$frames" --rate 10 --no-tf >/dev/null
else
  bag="$work/with_tf.bag"
  "$build/devel/lib/mc_flow/make_synthetic_bag" "$bag" --frames "$frames" --rate 10 >/dev/null
fi

xvfb_pid="" launch_pid=""
cleanup() {
  if [ -n "$launch_pid" ]; then kill -INT "$launch_pid" 2>/dev/null || true; wait "$launch_pid" 2>/dev/null || true; fi
  if [ -n "$xvfb_pid" ]; then kill "$xvfb_pid" 2>/dev/null || true; wait "$xvfb_pid" 2>/dev/null || true; fi
  rm -rf "$work"
}
trap cleanup EXIT

Xvfb "$display" -screen 0 1500x900x24 -nolisten tcp >"$work/xvfb.log" 2>&1 &
xvfb_pid=$!
sleep 2
echo "playing $bag ($([ "$fixed_frame" = auto ] && echo "only the three camera topics" || echo "with /tf_static")) with rviz on Xvfb $display, fixed_frame:=$fixed_frame"
DISPLAY="$display" LIBGL_ALWAYS_SOFTWARE=1 roslaunch -p "$port" mc_flow demo.launch bag:="$bag" rate:="$rate" \
    rviz:=true fixed_frame:="$fixed_frame" exit_when_done:=false save_dir:=none print_summary:=true >"$work/launch.log" 2>&1 &
launch_pid=$!

# The player registers, plays and exits; then the last pair is solved and drawn.
seen=0
for _ in $(seq 1 240); do
  if rosnode list 2>/dev/null | grep -qx /player; then seen=1
  elif [ "$seen" = 1 ]; then break; fi
  kill -0 "$launch_pid" 2>/dev/null || { cat "$work/launch.log" >&2; echo "rviz_screenshot.sh: roslaunch ended" >&2; exit 1; }
  sleep 0.5
done
[ "$seen" = 1 ] || { tail -30 "$work/launch.log" >&2; echo "rviz_screenshot.sh: the player never ran" >&2; exit 1; }
sleep "${SETTLE:-8}"
grep -E "Fixed Frame|rviz: .* view" "$work/launch.log" | tail -2 || true
mkdir -p "$(dirname "$png")"
shot="$(dirname "$png")/.rviz_screenshot_$$.png"
import -display "$display" -window root "$shot"
# A screen grabbed before rviz drew (seen once under load) is one flat colour: refuse it, keep the old picture.
spread=$(identify -format '%[fx:standard_deviation]' "$shot")
if awk -v s="$spread" 'BEGIN { exit !(s < 0.02) }'; then
  rm -f "$shot"
  echo "error: the screenshot is blank (pixel standard deviation $spread): rviz had not drawn yet; run again" >&2
  exit 1
fi
mv "$shot" "$png"
echo "wrote $png"
