#!/usr/bin/python3
"""Starts rviz on the MC-Flow outputs with a Fixed Frame that needs no TF.

Every output of the nodelet carries the frame_id of the colour image (its optical frame). A bag with only
the three input topics has no /tf_static, so a body frame such as camera_link does not exist there: rviz
then shows nothing in 3D. With fixed_frame:=auto this node waits for the nodelet's first ~camera_info and
starts rviz with `-f <its frame_id>`; any other value is passed to rviz as it is.

Private parameters: config (the .rviz file), fixed_frame (auto or a frame), outputs (the nodelet's name,
relative to this node's namespace; the config's topics start with mc_flow/), wait (s for the first output
before rviz starts with the config's own Fixed Frame).
"""
import os
import sys
import tempfile

import rospy
from sensor_msgs.msg import CameraInfo


def config_for(config, outputs):
    """The config with its relative output topics (mc_flow/...) pointed at `outputs`."""
    if outputs == "mc_flow":
        return config
    with open(config) as f:
        text = f.read()
    text = text.replace(": mc_flow/", ": %s/" % outputs)
    handle, path = tempfile.mkstemp(prefix="mc_flow_", suffix=".rviz")
    with os.fdopen(handle, "w") as f:
        f.write(text)
    return path


def main():
    rospy.init_node("rviz_frame_probe", anonymous=True)
    config = rospy.get_param("~config")
    fixed_frame = str(rospy.get_param("~fixed_frame", "auto")).strip()
    outputs = str(rospy.get_param("~outputs", "mc_flow")).strip("/")
    wait = float(rospy.get_param("~wait", 60.0))
    if not os.path.isfile(config):
        rospy.logfatal("rviz config %s does not exist", config)
        return 1
    if fixed_frame in ("", "auto"):
        topic = rospy.resolve_name(outputs + "/camera_info")
        rospy.loginfo("rviz: waiting up to %.0f s for %s to pick the Fixed Frame", wait, topic)
        try:
            info = rospy.wait_for_message(topic, CameraInfo, timeout=wait)
            fixed_frame = info.header.frame_id
            rospy.loginfo("rviz: Fixed Frame %s (the frame_id of the outputs; fixed_frame:= overrides it)",
                          fixed_frame)
        except rospy.ROSException:
            rospy.logwarn("rviz: no message on %s within %.0f s: starting rviz with the config's Fixed Frame; "
                          "check the nodelet's warnings for its input", topic, wait)
            fixed_frame = ""
    args = ["rviz", "-d", config_for(config, outputs)]
    if fixed_frame:
        args += ["-f", fixed_frame]
    # rviz takes over this process (and its remappings, __name and __ns): roslaunch sees one node.
    args += [a for a in sys.argv[1:] if ":=" in a]
    rospy.signal_shutdown("starting rviz")
    os.execvp("rviz", args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
