#!/usr/bin/python3
"""Starts rviz on the MC-Flow outputs with a Fixed Frame that needs no TF.

Every output of the nodelet carries the frame_id of the colour image (its optical frame). A bag with only
the three input topics has no /tf_static, so a body frame such as camera_link does not exist there: rviz
then shows nothing in 3D. With fixed_frame:=auto this node waits for the nodelet's first ~camera_info and
starts rviz with `-f <its frame_id>`; any other value is passed to rviz as it is.

The saved Orbit view (rviz/mc_flow.rviz) looks from the camera along +z of an optical Fixed Frame (REP 103:
x right, y down, z forward). rviz's orbit keeps the Fixed Frame's z up, so in a body frame such as
camera_link (REP 103: x forward, y left, z up) that view would look at the floor or the sky. The rule: the
outputs' own frame (fixed_frame:=auto) and any frame whose name contains "optical" get the optical view;
any other frame is taken as a body frame and gets the same view turned to look along its +x with z up.
Such a view is written to a copy of the config (in the temp folder, one per kind of view and outputs name).

Private parameters: config (the .rviz file), fixed_frame (auto or a frame), outputs (the nodelet's name,
relative to this node's namespace; the config's topics start with mc_flow/), wait (s for the first output
before rviz starts with the config's own Fixed Frame).
"""
import os
import re
import sys
import tempfile

import rospy
from sensor_msgs.msg import CameraInfo


# Orbit views (rviz places the eye at focal + distance * (cos yaw cos pitch, sin yaw cos pitch, sin pitch)
# and keeps the Fixed Frame's z up). Both put the eye at the frame's origin, i.e. at the camera, and the
# focal point 2.5 m ahead: as the camera sees, as in the image panels.
# The values are written into the config as they are (the optical one as the saved config has it).
OPTICAL_VIEW = {  # ahead = +z; pitch at rviz's limit (-pi/2 + 0.001), yaw 3pi/2 turns the image so that -y is up
    "Focal Point": ("0", "0", "2.5"), "Distance": "2.5", "Pitch": "-1.5697963", "Yaw": "4.712389"}
BODY_VIEW = {  # ahead = +x, z up: the eye 2.5 m behind the focal point along -x, level
    "Focal Point": ("2.5", "0", "0"), "Distance": "2.5", "Pitch": "0", "Yaw": "3.1415927"}


def is_optical(fixed_frame, from_outputs):
    """Whether the Fixed Frame is an optical frame (z forward): the outputs' own frame_id is one by REP 103
    (an image's frame), and so is any frame named like one (camera_rgb_optical_frame, ..._optical)."""
    return from_outputs or "optical" in fixed_frame.lower()


def with_view(text, view):
    """The config text with its current Orbit view's focal point, distance, pitch and yaw set to `view`."""
    start = text.index("\n  Views:\n")
    end = text.find("\n    Saved:", start)
    end = len(text) if end < 0 else end
    block = text[start:end]
    x, y, z = view["Focal Point"]
    block, n = re.subn(r"(\n( +)Focal Point:\n\2  X: )[^\n]*(\n\2  Y: )[^\n]*(\n\2  Z: )[^\n]*",
                       lambda m: m.group(1) + x + m.group(3) + y + m.group(4) + z, block)
    if n != 1:
        raise ValueError("no Focal Point X/Y/Z in the current view")
    for key in ("Distance", "Pitch", "Yaw"):
        block, n = re.subn(r"(\n +%s: )[^\n]*" % key, lambda m: m.group(1) + view[key], block)
        if n != 1:
            raise ValueError("no %s in the current view" % key)
    return text[:start] + block + text[end:]


def config_for(config, outputs, optical):
    """The config with its relative output topics (mc_flow/...) pointed at `outputs` and the Orbit view
    for an optical or a body Fixed Frame: the package's file itself where nothing changes, else a copy."""
    with open(config) as f:
        original = f.read()
    text = original
    if outputs != "mc_flow":
        text = text.replace(": mc_flow/", ": %s/" % outputs)
    text = with_view(text, OPTICAL_VIEW if optical else BODY_VIEW)
    if text == original:
        return config
    # One file per view and outputs name, replaced atomically: no temp file per start is left behind.
    path = os.path.join(tempfile.gettempdir(), "mc_flow_rviz_%d_%s_%s.rviz" % (
        os.getuid(), re.sub(r"[^A-Za-z0-9_]", "_", outputs), "optical" if optical else "body"))
    handle, partial = tempfile.mkstemp(prefix="mc_flow_rviz_", suffix=".partial")
    with os.fdopen(handle, "w") as f:
        f.write(text)
    os.replace(partial, path)
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
    from_outputs = fixed_frame in ("", "auto")
    if from_outputs:
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
    optical = is_optical(fixed_frame, from_outputs)
    try:
        view_config = config_for(config, outputs, optical)
    except ValueError as e:
        rospy.logwarn("rviz: %s has no Orbit view to set (%s): using it as it is", config, e)
        view_config = config
    rospy.loginfo("rviz: %s view (looking along %s)", "optical" if optical else "body frame",
                  "+z, y down" if optical else "+x, z up")
    args = ["rviz", "-d", view_config]
    if fixed_frame:
        args += ["-f", fixed_frame]
    # rviz takes over this process (and its remappings, __name and __ns): roslaunch sees one node.
    args += [a for a in sys.argv[1:] if ":=" in a]
    rospy.signal_shutdown("starting rviz")
    os.execvp("rviz", args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
