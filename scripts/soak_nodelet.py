#!/usr/bin/python3
"""Soak driver: publishes the frames of an RGB-D bag into a running MC-Flow nodelet, over and over, until
PAIRS pairs are solved, and prints a table of the nodelet manager's memory and the nodelet's counters.

The bag's frames are played forwards and backwards (0..n-1, n-2..1, ...), so the motion between two frames
is always one step of the bag's, with fresh stamps `--interval` s apart (stamps never repeat or go back).
Pacing: by default each frame is published when the pair ending at the previous one has come out
(lockstep: the solver is always busy and nothing is dropped); `--rate HZ` publishes at a fixed rate instead,
so frames that arrive during a solve are dropped, by design, and counted.

Every `--sample-every` pairs a row: pairs solved, frames published, wall time, pairs/s and the mean solve
time over the row's pairs (from ~segments), the manager's resident memory (VmRSS of the process that
runs the nodelet, found through its ROS node API), and the nodelet's own counts from /diagnostics (frames
dropped while solving, skipped as bad input, lost before the callbacks). The summary fits a line to the
resident memory after `--warmup` pairs: growth per 1000 pairs is what a leak would show.

Exit status: 0; 1 when the nodelet stops answering (no pair for `--timeout` s) or the process is gone;
2 when memory grows faster than `--max-growth` MB per 1000 pairs after the warm-up.
Started by scripts/soak_nodelet.sh, which also starts the master, the nodelet and makes the bag.
"""
import argparse
import collections
import sys
import threading
import time
import xmlrpc.client

import rosbag
import rosgraph
import rospy
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import CameraInfo, Image

from mc_flow.msg import SegmentArray

COUNTERS = {
    "dropped": "frames dropped (arrived while solving)",
    "skipped": "frames skipped (bad input)",
    "lost": "lost before the callbacks rgb / depth / camera_info (header.seq gaps)",
    "solved": "pairs solved",
}


def read_frames(path, rgb_topic, depth_topic, info_topic):
    """The bag's (rgb, depth, info) triples in stamp order; a triple needs all three at one stamp."""
    by_stamp = collections.defaultdict(dict)
    with rosbag.Bag(path) as bag:
        for topic, msg, _ in bag.read_messages(topics=[rgb_topic, depth_topic, info_topic]):
            by_stamp[msg.header.stamp][topic] = msg
    frames = [(m[rgb_topic], m[depth_topic], m[info_topic]) for _, m in sorted(by_stamp.items()) if len(m) == 3]
    if len(frames) < 2:
        raise SystemExit("soak: %s holds %d complete frames on %s, %s, %s; need 2 or more"
                         % (path, len(frames), rgb_topic, depth_topic, info_topic))
    return frames


def node_pid(node):
    """The pid of the process that runs ROS node `node` (its node API's getPid)."""
    uri = rosgraph.Master("/mc_flow_soak").lookupNode(node)
    code, message, pid = xmlrpc.client.ServerProxy(uri).getPid("/mc_flow_soak")
    if code != 1:
        raise RuntimeError("getPid of %s: %s" % (node, message))
    return int(pid)


def resident_mb(pid):
    """VmRSS of `pid` in MB, or None when the process is gone."""
    try:
        with open("/proc/%d/status" % pid) as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def slope_per_1000(points):
    """Least-squares slope of (pairs, MB) in MB per 1000 pairs; None with fewer than 2 points."""
    if len(points) < 2:
        return None
    n = float(len(points))
    mx = sum(p for p, _ in points) / n
    my = sum(m for _, m in points) / n
    sxx = sum((p - mx) ** 2 for p, _ in points)
    if sxx == 0:
        return None
    return 1000.0 * sum((p - mx) * (m - my) for p, m in points) / sxx


class Soak:
    def __init__(self, args):
        self.args = args
        self.lock = threading.Condition()
        self.solved_stamps = set()
        self.solve_ms = []        # of the pairs since the last row
        self.segment_counts = []  # idem
        self.pairs = 0
        self.counters = {}
        ns = args.camera.rstrip("/")
        outputs = ns + "/" + args.name
        self.pub_rgb = rospy.Publisher(ns + "/" + args.rgb_topic, Image, queue_size=5)
        self.pub_depth = rospy.Publisher(ns + "/" + args.depth_topic, Image, queue_size=5)
        self.pub_info = rospy.Publisher(ns + "/" + args.info_topic, CameraInfo, queue_size=5)
        rospy.Subscriber(outputs + "/segments", SegmentArray, self.on_segments, queue_size=50)
        rospy.Subscriber("/diagnostics", DiagnosticArray, self.on_diagnostics, queue_size=10)

    def on_segments(self, msg):
        with self.lock:
            self.pairs += 1
            self.solved_stamps.add(msg.header.stamp)
            self.solve_ms.append(msg.solve_time_ms)
            self.segment_counts.append(len(msg.segments))
            self.lock.notify_all()

    def on_diagnostics(self, msg):
        for status in msg.status:
            if "MC-Flow" not in status.name:
                continue
            values = {kv.key: kv.value for kv in status.values}
            with self.lock:
                for short, key in COUNTERS.items():
                    if key in values:
                        self.counters[short] = values[key]

    def wait_subscribed(self, timeout):
        end = time.time() + timeout
        while time.time() < end and not rospy.is_shutdown():
            if min(p.get_num_connections() for p in (self.pub_rgb, self.pub_depth, self.pub_info)) > 0:
                return True
            time.sleep(0.1)
        return False

    def run(self):
        args = self.args
        frames = read_frames(args.bag, "/" + args.camera.strip("/") + "/" + args.rgb_topic,
                             "/" + args.camera.strip("/") + "/" + args.depth_topic,
                             "/" + args.camera.strip("/") + "/" + args.info_topic)
        order = list(range(len(frames))) + list(range(len(frames) - 2, 0, -1))
        pid = node_pid(args.manager)
        if not self.wait_subscribed(60):
            print("soak: the nodelet did not subscribe to its inputs within 60 s", flush=True)
            return 1
        width, height = frames[0][0].width, frames[0][0].height
        print("soak: %d pairs, %d frames of %s (%dx%d) played forwards and backwards, %s, manager %s (pid %d)"
              % (args.pairs, len(frames), args.bag, width, height,
                 "lockstep" if args.rate <= 0 else "%.1f Hz" % args.rate, args.manager, pid), flush=True)
        header = ("%8s %9s %8s %8s %9s %7s %9s %8s %8s %10s"
                  % ("pairs", "published", "wall s", "pairs/s", "solve ms", "segs", "RSS MB", "dropped",
                     "skipped", "lost r/d/i"))
        print(header, flush=True)
        stamp = rospy.Time(args.start_stamp)
        published = 0
        start = time.time()
        row_start, row_pairs = start, 0
        samples = []  # (pairs, RSS MB)
        next_row = args.sample_every
        status = 0
        while not rospy.is_shutdown():
            with self.lock:
                pairs = self.pairs
            if pairs >= args.pairs:
                break
            rgb, depth, info = frames[order[published % len(order)]]
            stamp = stamp + rospy.Duration(args.interval)
            for msg in (rgb, depth, info):
                msg.header.stamp = stamp
            self.pub_info.publish(info)
            self.pub_depth.publish(depth)
            self.pub_rgb.publish(rgb)
            published += 1
            if args.rate > 0:
                time.sleep(max(0.0, start + published / args.rate - time.time()))
            elif published > 1:
                with self.lock:
                    if not self.lock.wait_for(lambda: stamp in self.solved_stamps, timeout=args.timeout):
                        print("soak: no pair ending at frame %d (stamp %.3f) within %.0f s"
                              % (published, stamp.to_sec(), args.timeout), flush=True)
                        status = 1
                        break
                    self.solved_stamps.discard(stamp)
            else:
                time.sleep(0.5)  # the first frame starts the sequence: no pair to wait for
            if args.rate > 0:
                with self.lock:
                    if self.pairs == 0 and time.time() - start > args.timeout:
                        print("soak: no pair within %.0f s" % args.timeout, flush=True)
                        status = 1
                        break
            with self.lock:
                pairs = self.pairs
            if pairs >= next_row or pairs >= args.pairs:
                rss = resident_mb(pid)
                if rss is None:
                    print("soak: the manager (pid %d) is gone" % pid, flush=True)
                    status = 1
                    break
                now = time.time()
                with self.lock:
                    solve = sum(self.solve_ms) / max(1, len(self.solve_ms))
                    segs = sum(self.segment_counts) / max(1, len(self.segment_counts))
                    self.solve_ms, self.segment_counts = [], []
                    counters = dict(self.counters)
                print("%8d %9d %8.1f %8.2f %9.1f %7.1f %9.1f %8s %8s %10s"
                      % (pairs, published, now - start, (pairs - row_pairs) / max(1e-9, now - row_start), solve, segs,
                         rss, counters.get("dropped", "-"), counters.get("skipped", "-"),
                         counters.get("lost", "-").replace(" ", "")), flush=True)
                samples.append((pairs, rss))
                row_start, row_pairs = now, pairs
                next_row = (pairs // args.sample_every + 1) * args.sample_every
        wall = time.time() - start
        time.sleep(2.5)  # /diagnostics comes once a second: let the counts catch up with the last frames
        with self.lock:
            pairs = self.pairs
            counters = dict(self.counters)
        after = [s for s in samples if s[0] >= args.warmup]
        growth = slope_per_1000(after)
        print("soak: %d pairs in %.0f s (%.2f pairs/s), %d frames published; dropped %s, skipped %s, lost %s"
              % (pairs, wall, pairs / max(wall, 1e-9), published, counters.get("dropped", "-"),
                 counters.get("skipped", "-"), counters.get("lost", "-")), flush=True)
        if samples:
            print("soak: manager RSS %.1f MB at the first row, %.1f MB after %d pairs (warm-up), %.1f MB at the end, "
                  "max %.1f MB" % (samples[0][1], after[0][1] if after else float("nan"), args.warmup, samples[-1][1],
                                   max(m for _, m in samples)), flush=True)
        if growth is None:
            print("soak: too few rows after the warm-up to fit the memory growth", flush=True)
        else:
            flat = growth <= args.max_growth
            print("soak: memory growth after the warm-up: %+.2f MB per 1000 pairs (%s; limit %.1f)"
                  % (growth, "flat" if flat else "GROWING", args.max_growth), flush=True)
            if not flat and status == 0:
                status = 2
        return status


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bag", required=True, help="bag with the three camera topics (make_synthetic_bag)")
    parser.add_argument("--pairs", type=int, default=10000, help="pairs to solve (10000)")
    parser.add_argument("--sample-every", type=int, default=100, help="pairs per table row (100)")
    parser.add_argument("--warmup", type=int, default=200, help="pairs before the memory fit starts (200)")
    parser.add_argument("--max-growth", type=float, default=2.0,
                        help="MB per 1000 pairs after the warm-up above which the run fails (2.0)")
    parser.add_argument("--rate", type=float, default=0.0, help="frames per second; 0: lockstep (0)")
    parser.add_argument("--interval", type=float, default=0.1, help="stamp step between frames [s] (0.1)")
    parser.add_argument("--timeout", type=float, default=60.0, help="[s] without a pair before giving up (60)")
    parser.add_argument("--start-stamp", type=float, default=100000.0, help="stamp of the first frame [s]")
    parser.add_argument("--camera", default="/camera", help="camera namespace (/camera)")
    parser.add_argument("--name", default="mc_flow", help="nodelet name (mc_flow)")
    parser.add_argument("--manager", default="/camera/mc_flow_manager", help="node name of the nodelet manager")
    parser.add_argument("--rgb-topic", default="rgb/image_rect_color")
    parser.add_argument("--depth-topic", default="depth_registered/image_rect")
    parser.add_argument("--info-topic", default="rgb/camera_info")
    args = parser.parse_args(rospy.myargv()[1:])
    rospy.init_node("mc_flow_soak", disable_signals=False)
    return Soak(args).run()


if __name__ == "__main__":
    sys.exit(main())
