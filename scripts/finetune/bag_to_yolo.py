#!/usr/bin/python3
"""Writes a YOLO-format folder from a drive bag's ground-truth boxes (python3-rosbag).

usage: python3 -m finetune.bag_to_yolo DRIVE.bag OUT_DIR [--cameras 0] [--every N] [--classes car,van,truck,bus]

For each /camN/detections_gt message, the /camN/image_raw frame with the same stamp is
written as OUT_DIR/images/<drive>_camN_<index>.png with OUT_DIR/labels/<same>.txt
(`class cx cy w h` normalised). Frames without a box get an empty label file.
"""
import argparse
import os
import sys

import cv2
import numpy as np


def image_to_array(msg):
    if msg.encoding != "mono8":
        raise ValueError(f"image encoding {msg.encoding}, expected mono8")
    return np.frombuffer(msg.data, np.uint8).reshape(msg.height, msg.step)[:, :msg.width]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("bag")
    p.add_argument("out")
    p.add_argument("--cameras", default="0", help="comma-separated camera indices (default 0)")
    p.add_argument("--every", type=int, default=1, help="keep every N-th frame (default 1)")
    p.add_argument("--classes", default="car,van,truck,bus", help="classes.txt contents, in order")
    a = p.parse_args(argv)
    import rosbag
    classes = a.classes.split(",")
    os.makedirs(os.path.join(a.out, "images"), exist_ok=True)
    os.makedirs(os.path.join(a.out, "labels"), exist_ok=True)
    with open(os.path.join(a.out, "classes.txt"), "w") as f:
        f.write("\n".join(classes) + "\n")
    drive = os.path.basename(os.path.dirname(os.path.abspath(a.bag)))
    cams = [int(c) for c in a.cameras.split(",")]
    topics = [f"/cam{c}/detections_gt" for c in cams] + [f"/cam{c}/image_raw" for c in cams]
    pending_img, pending_det, count = {}, {}, {c: 0 for c in cams}
    written = 0
    with rosbag.Bag(a.bag) as bag:
        for topic, msg, _ in bag.read_messages(topics=topics):
            cam = int(topic.split("/")[1][3:])
            key = (cam, msg.header.stamp.to_nsec())
            (pending_det if topic.endswith("detections_gt") else pending_img)[key] = msg
            if key not in pending_det or key not in pending_img:
                continue
            det, img = pending_det.pop(key), pending_img.pop(key)
            count[cam] += 1
            if (count[cam] - 1) % a.every:
                continue
            name = f"{drive}_cam{cam}_{count[cam] - 1:05d}"
            grey = image_to_array(img)
            h, w = grey.shape
            lines = []
            for d in det.detections:
                cls = classes.index(d.class_name) if d.class_name in classes else 0
                x0, y0 = max(0.0, d.x_min), max(0.0, d.y_min)
                x1, y1 = min(float(w), d.x_max), min(float(h), d.y_max)
                if x1 <= x0 or y1 <= y0:
                    continue
                lines.append(f"{cls} {(x0 + x1) / 2 / w:.6f} {(y0 + y1) / 2 / h:.6f} {(x1 - x0) / w:.6f} "
                             f"{(y1 - y0) / h:.6f}")
            cv2.imwrite(os.path.join(a.out, "images", name + ".png"), grey)
            with open(os.path.join(a.out, "labels", name + ".txt"), "w") as f:
                f.write("".join(line + "\n" for line in lines))
            written += 1
    print(f"{a.bag}: {written} frames written to {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
