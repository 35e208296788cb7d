#!/usr/bin/python3
"""Ends the demo: waits until the bag player has finished and the nodelet's last pair has come out,
then reports and exits (demo.launch marks this node required, so roslaunch then stops everything).

Parameters (private): segments_topic, input_topic (a topic the player publishes), save_dir,
settle (s to wait for results after the player is gone), first_result_timeout (s), timeout (s, whole demo).
"""
import os
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

    def run(self):
        start = time.monotonic()
        seen_player = False
        player_gone_at = None
        while not rospy.is_shutdown():
            now = time.monotonic()
            if now - start > self.timeout:
                rospy.logerr("demo did not finish within %.0f s (%d pairs solved)", self.timeout, self.results)
                return 1
            publishing = self.player_publishing()
            seen_player = seen_player or publishing
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
        return 0 if self.results > 0 else 1


if __name__ == "__main__":
    rospy.init_node("demo_monitor")
    sys.exit(Monitor().run())
