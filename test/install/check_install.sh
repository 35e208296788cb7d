#!/bin/bash
# The install space as a ROS user meets it (issue 30). Installs the already-built package (no rebuild) into a
# temporary folder, then, with only that prefix sourced (a clean environment, not the build's devel space):
#  1. the layout: nodelet + plugin description, messages, cfg header, launch, rviz, mcflow and make_synthetic_bag,
#     every header under include/mc_flow/ (not include/mc_flow/ros/ros), the static core libraries; no test harness;
#  2. a downstream catkin package (test/install/mc_flow_downstream) builds in a temporary workspace with
#     find_package(catkin REQUIRED COMPONENTS mc_flow) + ${catkin_LIBRARIES}, and its program solves a synthetic pair;
#  3. `rosrun mc_flow mcflow demo` from the install space writes its outputs;
#  4. demo.launch from the install space plays a 4-frame synthetic bag into the installed nodelet and ends with
#     status 0 (demo_monitor: at least one pair solved, the bag played out).
# Usage: check_install.sh SOURCE_DIR BUILD_DIR. Removes everything it made.
set -uo pipefail
src=$(cd "$1" && pwd)
build=$(cd "$2" && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/mc_flow_install.XXXXXX")
trap 'rm -rf "$work"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
# A staged install (DESTDIR, as a packager makes one) of the build's own install prefix: catkin writes the setup files to
# that prefix as an absolute path, so `cmake --install --prefix` would put them outside the temporary folder. setup.bash
# finds its own folder, and the package's CMake config finds its libraries through CMAKE_PREFIX_PATH.
configured=$(sed -n 's/^CMAKE_INSTALL_PREFIX:PATH=//p' "$build/CMakeCache.txt")
[ -n "$configured" ] || fail "no CMAKE_INSTALL_PREFIX in $build/CMakeCache.txt"
prefix=$work/stage$configured
start=$SECONDS
DESTDIR="$work/stage" cmake --install "$build" >"$work/install.log" 2>&1 || { tail -20 "$work/install.log"; fail "cmake --install"; }
echo "ok   installed into a temporary folder in $((SECONDS - start)) s"

# 1. layout
for f in setup.bash lib/libmc_flow_nodelet.so share/mc_flow/nodelet_plugins.xml share/mc_flow/package.xml \
         share/mc_flow/launch/demo.launch share/mc_flow/launch/mc_flow.launch share/mc_flow/rviz/mc_flow.rviz \
         share/mc_flow/cmake/mc_flowConfig.cmake share/mc_flow/cmake/mc_flow-extras.cmake share/mc_flow/msg/SegmentArray.msg \
         include/mc_flow/McFlowConfig.h include/mc_flow/SegmentArray.h include/mc_flow/MotionSegment.h \
         include/mc_flow/core/solver.h include/mc_flow/core/config_fields.def include/mc_flow/eval/synthetic_scene.h \
         include/mc_flow/io/image_io.h include/mc_flow/ros/conversions.h \
         include/mc_flow/cli/command_line.h lib/libmc_flow_cli.a \
         lib/libmc_flow_core.a lib/libmc_flow_eval.a lib/libmc_flow_formats.a lib/libmc_flow_io.a \
         lib/mc_flow/mcflow lib/mc_flow/make_synthetic_bag lib/mc_flow/demo_monitor.py lib/mc_flow/start_rviz.py; do
  [ -e "$prefix/$f" ] || fail "the install space has no $f"
done
for f in include/mc_flow/ros/ros include/mc_flow/testing lib/libmc_flow_testing.a; do
  [ ! -e "$prefix/$f" ] || fail "the install space has $f (test harness or a misplaced folder)"
done
echo "ok   layout: nodelet, messages, cfg, launch, rviz, tools, headers under include/mc_flow, core libraries; no test harness"

# Everything below runs with the install space alone: a clean environment, /usr/bin first (Debian's ROS python).
in_install() {
  env -i HOME="$work/home" PATH=/usr/bin:/bin TMPDIR="$work" OMP_WAIT_POLICY=passive \
      bash -c 'set -uo pipefail; set +u; source "$0/setup.bash"; set -u; eval "$1"' "$prefix" "$1"
}
mkdir -p "$work/home"
found=$(in_install 'rospack find mc_flow') || fail "rospack find mc_flow: $found"
[ "$found" = "$prefix/share/mc_flow" ] || fail "rospack find mc_flow gives '$found', not the install space"
plugins=$(in_install 'rospack plugins --attrib=plugin nodelet' 2>&1 | grep "^mc_flow ")
[ "$plugins" = "mc_flow $prefix/share/mc_flow/nodelet_plugins.xml" ] || fail "nodelet finds mc_flow's plugin at '$plugins'"

# 2. a downstream package
mkdir -p "$work/ws/src"
cp -r "$src/test/install/mc_flow_downstream" "$work/ws/src/"
start=$SECONDS
in_install "cd '$work/ws' && catkin_make -j2 -DCMAKE_BUILD_TYPE=Release -DCATKIN_ENABLE_TESTING=OFF" >"$work/downstream.log" 2>&1 ||
  { tail -30 "$work/downstream.log"; fail "the downstream package does not build against the install space"; }
out=$(in_install "'$work/ws/devel/lib/mc_flow_downstream/solve_synthetic_pair'" 2>&1) ||
  fail "the downstream program: $out"
echo "ok   downstream package built against the install space in $((SECONDS - start)) s and solved a pair: $out"

# 3. the command-line tool
out=$(in_install "rosrun mc_flow mcflow demo --out '$work/demo'" 2>&1) || fail "rosrun mc_flow mcflow demo: $(echo "$out" | tail -5)"
for f in overview.png segments.json report.json optical_flow.flo; do
  [ -s "$work/demo/$f" ] || fail "mcflow demo wrote no $f"
done
echo "ok   rosrun mc_flow mcflow demo from the install space"

# 4. the demo launch: a short bag, played slowly enough that each pair is solved before the next frame
port=$((11900 + RANDOM % 500))
in_install "rosrun mc_flow make_synthetic_bag '$work/demo.bag' --frames 4 --width 160 --height 120" >"$work/bag.log" 2>&1 ||
  { cat "$work/bag.log"; fail "rosrun mc_flow make_synthetic_bag"; }
in_install "export ROS_MASTER_URI=http://localhost:$port ROS_HOME='$work/home/.ros'; cd '$work' &&
            timeout 300 roslaunch -p $port mc_flow demo.launch bag:=demo.bag rate:=0.5 rviz:=false save_dir:=none \
            status_file:='$work/status'" >"$work/launch.log" 2>&1
status=$(cat "$work/status" 2>/dev/null)
[ "$(echo "$status" | cut -d' ' -f1)" = 0 ] || { tail -30 "$work/launch.log"; fail "demo.launch status '$status'"; }
echo "ok   demo.launch from the install space: status 0"
