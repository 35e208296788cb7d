#!/usr/bin/env bash
# Installs the Debian 12 packages mc_flow needs (ROS 1 from Debian, OpenCV, Eigen, gtest) and the tools
# a ROS user reaches for (rviz, rosmsg, rosservice, dynparam, rostopic with every message type the package
# publishes, rosnode, rosrun, rosbag). Idempotent.
# Headless machines: MCFLOW_NO_RVIZ=1 (or --no-rviz) skips rviz, Xvfb and ImageMagick.
# --fuzz adds clang 14 with its sanitizer and libFuzzer runtimes and OpenMP, for the sanitized build that also runs the
# fuzz smoke (scripts/test_sanitized.sh core-io; scripts/test.sh passes it).
set -euo pipefail
NO_RVIZ="${MCFLOW_NO_RVIZ:-0}"
FUZZ=0
for arg in "$@"; do
  case "$arg" in
    --no-rviz) NO_RVIZ=1 ;;
    --fuzz) FUZZ=1 ;;
    *) echo "install_deps.sh: unknown argument '$arg' (--no-rviz, --fuzz)" >&2; exit 2 ;;
  esac
done
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
PACKAGES=(
  build-essential cmake pkg-config
  catkin libroscpp-dev libnodeletlib-dev libnodeletlib-tools pluginlib-dev libmessage-filters-dev
  libcv-bridge-dev libimage-transport-dev libsensor-msgs-dev libgeometry-msgs-dev libstd-msgs-dev
  libvisualization-msgs-dev ros-std-msgs ros-geometry-msgs ros-sensor-msgs ros-visualization-msgs
  libnav-msgs-dev ros-nav-msgs python3-nav-msgs
  ros-message-generation ros-message-runtime libdynamic-reconfigure-config-init-mutex-dev
  python3-dynamic-reconfigure libtf2-ros-dev libtf2-eigen-dev libdiagnostic-updater-dev
  libpcl-conversions-dev librosbag-dev librostest-dev python3-rostest python3-roslaunch python3-rosmaster
  python3-rosbag python3-rostopic python3-rosnode python3-sensor-msgs python3-geometry-msgs rosbash
  libgtest-dev libeigen3-dev libopencv-dev nlohmann-json3-dev libyaml-cpp-dev
  # the format check of every C++ file (scripts/check_format.sh, ctest format.ClangFormat)
  clang-format-14
  # command-line tools: rosmsg, rosservice (dynparam needs it), rosnode, rosdiagnostic, image_transport's
  # list_transports; Python messages for rostopic of every output type (sensor_msgs, visualization_msgs,
  # tf2_msgs, diagnostic_msgs, dynamic_reconfigure; mc_flow's own come from the build)
  python3-rosmsg python3-rosservice rosdiagnostic image-transport-tools python3-visualization-msgs
  python3-diagnostic-msgs python3-tf2-msgs ros-tf2-msgs ros-diagnostic-msgs python3-roslib
)
# The viewer (about 20 MB of archives on top of the above): rviz, and Xvfb + ImageMagick for
# scripts/rviz_screenshot.sh.
VIEWER=(rviz xvfb imagemagick)
if [ "$NO_RVIZ" = "1" ]; then
  echo "[install_deps] MCFLOW_NO_RVIZ=1 / --no-rviz: skipping ${VIEWER[*]}"
else
  PACKAGES+=("${VIEWER[@]}")
fi
if [ "$FUZZ" = "1" ]; then
  PACKAGES+=(clang-14 libclang-rt-14-dev libomp-14-dev)
fi
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "[install_deps] installing ${#missing[@]} packages: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
  echo "[install_deps] all packages present"
fi
