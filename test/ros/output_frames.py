#!/usr/bin/python3
"""Records the frame_id of every MC-Flow output (and of every marker) until each has arrived or
`timeout` s pass; prints one line per output and exits 1 when one did not arrive.
Usage: output_frames.py NAMESPACE (e.g. /camera/mc_flow) TIMEOUT"""
import sys
import time

import rospy
from mc_flow.msg import SegmentArray
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from visualization_msgs.msg import MarkerArray

ns, timeout = sys.argv[1].rstrip("/"), float(sys.argv[2])
outputs = {"segments": SegmentArray, "soft_labels": Image, "labels": Image, "segmentation": Image,
           "occlusion": Image, "scene_flow": PointCloud2, "motion_markers": MarkerArray, "camera_info": CameraInfo}
frames = {}


def keep(name):
    def callback(msg):
        if isinstance(msg, MarkerArray):
            ids = {m.header.frame_id for m in msg.markers if m.action != m.DELETEALL}
            if ids:
                frames[name] = ids
        else:
            frames[name] = {msg.header.frame_id}
    return callback


rospy.init_node("output_frames", anonymous=True, disable_signals=True)
subscribers = [rospy.Subscriber(ns + "/" + n, t, keep(n), queue_size=2) for n, t in outputs.items()]
end = time.monotonic() + timeout
while time.monotonic() < end and len(frames) < len(outputs):
    time.sleep(0.2)
for name in outputs:
    print("FRAME %s %s" % (name, " ".join(sorted(frames.get(name, {"<none>"})))))
sys.exit(0 if len(frames) == len(outputs) else 1)
