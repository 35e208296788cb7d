#!/usr/bin/env bash
# Installs the Debian 12 packages mc_flow needs (ROS 1 from Debian, OpenCV, Eigen, gtest). Idempotent.
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
PACKAGES=(
  build-essential cmake pkg-config
  catkin libroscpp-dev libnodeletlib-dev libnodeletlib-tools pluginlib-dev libmessage-filters-dev
  libcv-bridge-dev libimage-transport-dev libsensor-msgs-dev libgeometry-msgs-dev libstd-msgs-dev
  libvisualization-msgs-dev ros-std-msgs ros-geometry-msgs ros-sensor-msgs ros-visualization-msgs
  ros-message-generation ros-message-runtime libdynamic-reconfigure-config-init-mutex-dev
  python3-dynamic-reconfigure libtf2-ros-dev libtf2-eigen-dev libdiagnostic-updater-dev
  libpcl-conversions-dev librosbag-dev librostest-dev python3-rostest python3-roslaunch python3-rosmaster
  python3-rosbag python3-rostopic python3-rosnode python3-sensor-msgs python3-geometry-msgs rosbash
  libgtest-dev libeigen3-dev libopencv-dev nlohmann-json3-dev libyaml-cpp-dev
)
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
