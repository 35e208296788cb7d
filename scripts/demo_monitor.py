#!/usr/bin/python3
"""Ends the demo: waits until the bag player has finished and the nodelet's last pair has come out,
then reports, and ends the roslaunch that started it the way Ctrl-C does (see end_launch).

Parameters (private): segments_topic, input_topic (a topic the player publishes), player (its node name),
bag (its path, for messages), save_dir, status_file (gets "0" or "1 <reason>": roslaunch exits 0 either
way, so scripts read this), settle (s to wait for results after the player is gone),
first_result_timeout (s), timeout (s, whole demo).
"""
import os
import signal
import sys
import time

import rosgraph
import rospy


class Monitor:
    def __init__(self):
        self.segments_topic = rospy.get_param("~segments_topic", "/camera/mc_flow/segments")
        self.input_topic = rospy.get_param("~input_topic", "/camera/rgb/image_rect_color")
        self.save_dir = rospy.get_param("~save_dir", "")
        self.settle = float(rospy.get_param("~settle", 3.0))
        self.timeout = float(rospy.get_param("~timeout", 900.0))
        self.first_result_timeout = float(rospy.get_param("~first_result_timeout", 120.0))
        self.player = rospy.get_param("~player", "/player")
        self.bag = rospy.get_param("~bag", "")
        self.status_file = rospy.get_param("~status_file", "")
        self.results = 0
        self.last_result = None
        self.longest_gap = 0.0
        self.master = rosgraph.Master(rospy.get_name())
        # AnyMsg: no need for this package's Python messages, and no deserialisation cost.
        rospy.Subscriber(self.segments_topic, rospy.AnyMsg, self.on_result, queue_size=10)

    def on_result(self, _msg):
        now = time.monotonic()
        if self.last_result is not None:
            self.longest_gap = max(self.longest_gap, now - self.last_result)
        self.last_result = now
        self.results += 1

    def player_publishing(self):
        try:
            publishers, _, _ = self.master.getSystemState()
        except Exception:  # master gone: roslaunch is shutting down
            return False
        return any(topic == self.input_topic and nodes for topic, nodes in publishers)

    def player_alive(self):
        try:
            self.master.lookupNode(self.player)
            return True
        except Exception:  # not registered (exited), or the master is gone
            return False

    def fail(self, reason):
        rospy.logerr("demo failed: %s", reason)
        print("demo failed: %s" % reason, file=sys.stderr, flush=True)
        self.write_status("1 " + reason)
        return 1

    def write_status(self, text):
        if self.status_file:
            with open(self.status_file, "w") as f:
                f.write(text + "\n")

    def run(self):
        start = time.monotonic()
        seen_player = False
        player_registered = False
        player_gone_at = None
        while not rospy.is_shutdown():
            now = time.monotonic()
            if now - start > self.timeout:
                return self.fail("the demo did not finish within %.0f s (%d pairs solved)" % (self.timeout, self.results))
            publishing = self.player_publishing()
            seen_player = seen_player or publishing
            alive = self.player_alive()
            player_registered = player_registered or alive
            # The player ended without ever publishing the input (or ended before this node saw it
            # register): it could not open or read the bag (its own message is above, on the screen),
            # or the bag has other topic names.
            if not seen_player and not alive and (player_registered or now - start > 20.0):
                return self.fail("the bag player %s ended without publishing %s: see its message above; "
                                 "`rosbag info %s` lists the bag's topics (camera:= and the *_topic "
                                 "arguments select them)" % (self.player, self.input_topic, self.bag))
            if seen_player and not publishing and player_gone_at is None:
                player_gone_at = now
                rospy.loginfo("the bag has been played; waiting for the last pairs")
            if player_gone_at is not None:
                # The last frame may still be in the solver: wait at least the longest gap seen so far.
                quiet_since = max(player_gone_at, self.last_result or player_gone_at)
                # Before the first result the solve time is unknown: allow first_result_timeout.
                wait = max(self.settle, 1.5 * self.longest_gap) if self.results > 0 else self.first_result_timeout
                if now - quiet_since > wait:
                    break
            time.sleep(0.2)
        pictures = ""
        if self.save_dir and os.path.isdir(self.save_dir):
            count = len([f for f in os.listdir(self.save_dir) if f.endswith(".png")])
            pictures = "; %d pictures in %s" % (count, self.save_dir)
        rospy.loginfo("demo finished: %d pairs solved%s", self.results, pictures)
        print("demo finished: %d pairs solved%s" % (self.results, pictures), flush=True)
        if self.results == 0:
            return self.fail("the bag was played but no pair was solved: see the nodelet's warnings above")
        self.write_status("0")
        return 0


def end_launch():
    """Sends SIGINT, as Ctrl-C does, to the roslaunch that started this node: its normal shutdown. A node
    marked required would end the launch too, but roslaunch reports the end of a required node, a
    successful one included, as a red 'REQUIRED process [...] has died!'. Started otherwise (rosrun), the
    parent is left alone."""
    parent = os.getppid()
    try:
        with open("/proc/%d/cmdline" % parent, "rb") as f:
            command = f.read().split(b"\0")
    except OSError:
        return
    if any(os.path.basename(part) == b"roslaunch" for part in command[:2]):
        os.kill(parent, signal.SIGINT)


if __name__ == "__main__":
    rospy.init_node("demo_monitor")
    code = Monitor().run()
    if not rospy.is_shutdown():
        end_launch()
    sys.exit(code)
