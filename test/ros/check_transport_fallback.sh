#!/bin/bash
# A standalone nodelet asked for an image_transport whose plug-in is not installed (Debian 12 packages
# only raw; `compressed` stands for any missing one, MCFLOW_MISSING_TRANSPORT picks another):
#  1. says so, naming the transport and the installed ones;
#  2. subscribes to the raw topics (not the missing transport's) and stays up;
#  3. exits 0 on SIGINT (roscpp's own shutdown) and dies of the signal itself on SIGTERM: no crash.
# In a standalone nodelet `~image_transport` is the process's own private parameter, which
# image_transport's TransportHints read again for the raw fallback; the exception that followed made
# nodelet's loader destroy the nodelet after its callback queues: exit 139 right after start-up.
# Usage: check_transport_fallback.sh DEVEL_DIR
set -uo pipefail
devel=$1
missing=${MCFLOW_MISSING_TRANSPORT:-compressed}
export PATH="/usr/bin:$PATH"
set +u
# shellcheck disable=SC1091
source "$devel/setup.bash"
set -u
port=$((11900 + RANDOM % 500))
export ROS_MASTER_URI="http://localhost:$port"
work=$(mktemp -d /tmp/mc_flow_transport.XXXXXX)
master=""
node=""
cleanup() {
  [ -n "$node" ] && kill -KILL "$node" 2>/dev/null
  [ -n "$master" ] && { kill -INT "$master" 2>/dev/null; wait "$master" 2>/dev/null; }
  rm -rf "$work"
}
trap cleanup EXIT
fail() { echo "FAIL: $*"; [ -f "$work/node.log" ] && tail -20 "$work/node.log"; exit 1; }

roscore -p "$port" >"$work/master.log" 2>&1 &
master=$!
for _ in $(seq 1 60); do rosparam list >/dev/null 2>&1 && break; sleep 0.5; done
rosparam list >/dev/null 2>&1 || fail "no master on port $port"

# Whether node $1 subscribes to topic $2.
subscribes() { rostopic info "$2" 2>/dev/null | sed -n '/^Subscribers:/,$p' | grep -q "/$1 "; }

# Starts the nodelet (its node name: $1) and waits until it subscribed to its three inputs; sets $node.
start_nodelet() {
  /usr/lib/nodelet/nodelet standalone mc_flow/MCFlowNodelet __name:="$1" _image_transport:="$missing" \
      _print_summary:=true >"$work/node.log" 2>&1 &
  node=$!
  for _ in $(seq 1 120); do
    kill -0 "$node" 2>/dev/null || { wait "$node"; fail "$1 ended by itself (exit $?) before subscribing"; }
    subscribes "$1" /rgb/image_rect_color && subscribes "$1" /depth_registered/image_rect &&
      subscribes "$1" /rgb/camera_info && return 0
    sleep 0.5
  done
  fail "$1 did not subscribe to its three inputs within 60 s"
}

# Sends signal $1 to the nodelet and waits up to 30 s; sets $rc to its exit status.
stop_nodelet() {
  kill "-$1" "$node"
  for _ in $(seq 1 60); do kill -0 "$node" 2>/dev/null || break; sleep 0.5; done
  kill -0 "$node" 2>/dev/null && fail "still running 30 s after SIG$1"
  wait "$node"
  rc=$?
  node=""
}

start_nodelet mc_flow_int
grep -q "image_transport '$missing' is not installed (installed:.*raw.*): .*subscribing with 'raw' instead" "$work/node.log" ||
  fail "no error naming the missing transport '$missing' and the installed ones"
echo "ok   names the missing transport: $(grep -o "image_transport '$missing' is not installed ([^)]*)" "$work/node.log")"
for topic in /rgb/image_rect_color /depth_registered/image_rect; do
  subscribes mc_flow_int "$topic/$missing" && fail "subscribed to $topic/$missing"
done
sleep 2  # the worker and the 1 s diagnostics timer run: the crash came right after start-up
kill -0 "$node" 2>/dev/null || fail "died after subscribing"
echo "ok   subscribed with raw (colour and depth) and still running"
stop_nodelet INT
[ "$rc" = 0 ] || fail "SIGINT: exit $rc, expected 0"
echo "ok   SIGINT: exit 0"

start_nodelet mc_flow_term
sleep 2
stop_nodelet TERM
[ "$rc" = 143 ] || fail "SIGTERM: exit $rc, expected 143 (ended by the signal, not a crash)"
echo "ok   SIGTERM: exit 143 (ended by the signal)"
