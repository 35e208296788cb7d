#!/usr/bin/python3
"""The rviz view follows the Fixed Frame (scripts/start_rviz.py): the outputs' own frame (fixed_frame:=auto)
and frames named *optical* get a view along +z from the camera; any other frame (camera_link: REP 103 body
frame, x forward, z up) a view along +x with z up, from the camera too. Computed from the Orbit view that
rviz reads (eye = focal + distance * (cos yaw cos pitch, sin yaw cos pitch, sin pitch), the Fixed Frame's z
kept up), in the config that start_rviz.py hands to rviz.

Usage: check_rviz_view.py SOURCE_DIR
"""
import math
import os
import re
import sys


def orbit(text):
    """(eye, unit direction) of the current Orbit view in an .rviz text."""
    block = text[text.index("\n  Views:\n"):text.index("\n    Saved:")]
    focal = [float(v) for v in re.search(r"Focal Point:\n +X: (\S+)\n +Y: (\S+)\n +Z: (\S+)", block).groups()]
    value = lambda key: float(re.search(r"\n +%s: (\S+)" % key, block).group(1))
    d, yaw, pitch = value("Distance"), value("Yaw"), value("Pitch")
    offset = [d * math.cos(yaw) * math.cos(pitch), d * math.sin(yaw) * math.cos(pitch), d * math.sin(pitch)]
    eye = [f + o for f, o in zip(focal, offset)]
    return eye, [-o / d for o in offset]


def main():
    source = sys.argv[1]
    sys.path.insert(0, os.path.join(source, "scripts"))
    import start_rviz  # noqa: E402 (the script under test)

    config = os.path.join(source, "rviz", "mc_flow.rviz")
    failures = []

    def check(what, condition):
        print(("ok   " if condition else "FAIL ") + what)
        if not condition:
            failures.append(what)

    for frame, from_outputs, optical in (("camera_rgb_optical_frame", True, True), ("camera", True, True),
                                         ("camera_color_optical_frame", False, True),
                                         ("camera_link", False, False), ("base_link", False, False)):
        check("%s%s: %s view" % (frame, " (auto)" if from_outputs else "", "optical" if optical else "body"),
              start_rviz.is_optical(frame, from_outputs) == optical)

    # The package's config is the optical view itself: rviz gets the file (a user's save goes there).
    check("optical view, outputs mc_flow: the package's config as it is",
          start_rviz.config_for(config, "mc_flow", True) == config)
    for optical, ahead in ((True, [0, 0, 1]), (False, [1, 0, 0])):
        path = start_rviz.config_for(config, "mc_flow", optical)
        with open(path) as f:
            eye, direction = orbit(f.read())
        kind = "optical" if optical else "body"
        check("%s view: eye at the camera (%s)" % (kind, ", ".join("%.3f" % v for v in eye)),
              all(abs(v) < 0.01 for v in eye))  # 1 cm: rviz keeps the pitch 0.001 rad off the pole
        check("%s view: looks along %s (%s)" % (kind, ahead, ", ".join("%.4f" % v for v in direction)),
              sum(a * b for a, b in zip(ahead, direction)) > 0.9999)
    # Other outputs name: topics renamed, same view.
    path = start_rviz.config_for(config, "flow2", False)
    with open(path) as f:
        text = f.read()
    check("outputs flow2: topics renamed", ": flow2/" in text and ": mc_flow/" not in text)
    check("outputs flow2, body view: looks along +x", orbit(text)[1][0] > 0.9999)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
