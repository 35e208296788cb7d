#!/bin/bash
# Every ROS tool the README tells users to run is installed and starts (scripts/install_deps.sh installs
# them), and rostopic can load the message class of every type the package publishes.
# Usage: check_tools.sh README.md DEVEL_DIR. rviz is skipped, visibly, under MCFLOW_NO_RVIZ=1.
set -uo pipefail
readme=$1
devel=$2
export PATH="/usr/bin:$PATH"   # Debian's ROS python tools, not a pyenv python3
set +u
# shellcheck disable=SC1091
source "$devel/setup.bash"
set -u
failures=0
# Tool names that appear in the README's code (blocks and `inline`).
tools=$(awk '/^```/{inblock=!inblock; next} inblock{print; next} {while (match($0, /`[^`]*`/)) {print substr($0, RSTART+1, RLENGTH-2); $0=substr($0, RSTART+RLENGTH)}}' "$readme" |
        grep -oE '(^|[[:space:];(|&])(ros[a-z_]+|rviz|dynparam)\b' | tr -d ' \t;(|&' | sort -u)
[ -n "$tools" ] || { echo "FAIL: no ROS tools found in $readme"; exit 1; }
# (grep reads a here-string, not a pipe: under pipefail `echo | grep -q` could fail with SIGPIPE on a long output.)
starts() {
  out=$("${cmd[@]}" 2>&1)
  rc=$?
  [ "$rc" != 127 ] && grep -qiE "usage|commands:|--fixed-frame" <<<"$out" &&
    ! grep -qE "Traceback|No module named|command not found" <<<"$out"
}
for tool in $tools; do
  case "$tool" in
    rviz)
      if [ "${MCFLOW_NO_RVIZ:-0}" = "1" ]; then echo "SKIP rviz (MCFLOW_NO_RVIZ=1)"; continue; fi
      cmd=(env QT_QPA_PLATFORM=offscreen rviz -h) ;;
    dynparam) cmd=(rosrun dynamic_reconfigure dynparam -h) ;;
    roslaunch|rosbag|rostopic|rosmsg|rosservice|rosnode|rosrun|rosparam) cmd=("$tool" -h) ;;
    rosdep|ros_*) echo "SKIP $tool (not a runtime tool)"; continue ;;
    *) cmd=("$tool" -h) ;;
  esac
  # Most ROS tools print their usage for -h and exit 64 (rviz: 1): judge by what they print. A missing
  # tool (exit 127) or Python module (a traceback, as dynparam without rosservice) fails. A tool that fails is
  # started once more, visibly (one full ctest run here saw this check fail once, with its output lost, while
  # rerunning it under load never failed again): a missing tool or module fails both times.
  if starts; then
    echo "ok   $tool"
  else
    echo "RETRY $tool: '${cmd[*]}' exited $rc: $(echo "$out" | grep -v '^\s*$' | tail -5)"
    if starts; then
      echo "ok   $tool (second start)"
    else
      echo "FAIL $tool: '${cmd[*]}' exited $rc: $(echo "$out" | grep -v '^\s*$' | tail -5)"
      failures=$((failures + 1))
    fi
  fi
done
# Every type the nodelet publishes (outputs, /tf, /diagnostics, dynamic_reconfigure), as rostopic loads it.
python3 - <<'PY' || failures=$((failures + 1))
import sys
import roslib.message
types = ["mc_flow/SegmentArray", "sensor_msgs/Image", "sensor_msgs/PointCloud2", "sensor_msgs/CameraInfo",
         "visualization_msgs/MarkerArray", "tf2_msgs/TFMessage", "diagnostic_msgs/DiagnosticArray",
         "dynamic_reconfigure/Config", "dynamic_reconfigure/ConfigDescription", "rosgraph_msgs/Log"]
missing = [t for t in types if roslib.message.get_message_class(t) is None]
for t in types:
    print(("FAIL cannot load message class for [%s]" if t in missing else "ok   message %s") % t)
sys.exit(1 if missing else 0)
PY
if [ "$failures" -gt 0 ]; then echo "$failures tool check(s) failed"; exit 1; fi
echo "all tools present"
