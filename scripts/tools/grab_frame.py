#!/usr/bin/env python3
"""Saves one frame of the running pipeline, mid-drive: the reference camera's
image, its depth, and the detector's image (boxes drawn), all of the same
stamp, as PNGs (the inputs of Fig. 1 (a)-(c): scripts/tools/make_fig1.py).

usage: grab_frame.py OUT_DIR [--frame N] [--ns /fisheye_mapping]
                     [--image /cam0/image_raw] [--max-range 15] [--timeout S]
                     [--boxes TOPIC]

Waits for the N-th reference image (default 100: the middle of the demo's
200 frame sets), then for the depth map and the detections image of that
stamp (or of the first later stamp that has all three), writes
OUT_DIR/frame_image.png (grey), frame_depth.png (range colour-mapped over
[0, max-range] m, black = no depth), frame_depth_masked.png (the mask
stage's colour image, when published), frame_detections.png, and last
OUT_DIR/frame.txt (the stamp and the frame's index); then exits 0.
--boxes TOPIC: no detector image is waited for; the boxes of that
fisheye_mapping/Detection2DArray topic (e.g. the drive's true boxes,
/cam0/detections_gt, with vehicle.launch detector:=ground_truth, which runs
no detector) are drawn on the reference image instead (needs the built
workspace sourced for the message type).
Exits 1 after --timeout seconds (default 900) without a frame.
"""
import argparse
import os
import sys
import threading

import cv2
import numpy as np
import rospy
from sensor_msgs.msg import Image


def to_array(msg):
    """sensor_msgs/Image -> numpy (mono8, bgr8, rgb8, bgra8, rgba8, 32FC1, 16UC1)."""
    enc = msg.encoding.lower()
    chans = {"mono8": (np.uint8, 1), "8uc1": (np.uint8, 1), "bgr8": (np.uint8, 3), "rgb8": (np.uint8, 3),
             "8uc3": (np.uint8, 3), "bgra8": (np.uint8, 4), "rgba8": (np.uint8, 4), "32fc1": (np.float32, 1),
             "16uc1": (np.uint16, 1), "mono16": (np.uint16, 1)}
    if enc not in chans:
        raise ValueError(f"unsupported encoding {msg.encoding}")
    dtype, c = chans[enc]
    itemsize = np.dtype(dtype).itemsize
    a = np.frombuffer(msg.data, dtype=np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<"))
    a = a.reshape(msg.height, msg.step // itemsize)[:, : msg.width * c].reshape(msg.height, msg.width, c)
    a = a.astype(dtype)
    if enc == "rgb8":
        a = a[:, :, ::-1]
    elif enc == "rgba8":
        a = a[:, :, [2, 1, 0]]
    elif enc == "bgra8":
        a = a[:, :, :3]
    return a[:, :, 0] if c == 1 else np.ascontiguousarray(a)


def colour_depth(depth, max_range):
    """Range (m, NaN invalid) -> BGR: turbo over [0, max_range], near = red, black where invalid."""
    valid = np.isfinite(depth) & (depth > 0)
    scaled = np.clip(np.nan_to_num(depth, nan=0.0) / max_range, 0, 1)
    img = cv2.applyColorMap((255 * (1 - scaled)).astype(np.uint8), cv2.COLORMAP_TURBO)
    img[~valid] = 0
    return img


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--frame", type=int, default=100)
    ap.add_argument("--ns", default="/fisheye_mapping")
    ap.add_argument("--image", default="/cam0/image_raw")
    ap.add_argument("--max-range", type=float, default=15.0)
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--boxes")
    args = ap.parse_args(rospy.myargv()[1:])
    os.makedirs(args.out, exist_ok=True)
    topics = {"image": args.image, "depth": args.ns + "/depth/image",
              "detections": args.ns + "/detections/image", "depth_masked": args.ns + "/depth_masked/colour"}
    types = {k: Image for k in topics}
    if args.boxes:
        from fisheye_mapping.msg import Detection2DArray
        topics["detections"] = args.boxes
        types["detections"] = Detection2DArray
    lock = threading.Lock()
    seen = {k: {} for k in topics}   # key -> {stamp: msg}
    order = []                        # reference image stamps in arrival order
    done = threading.Event()

    def maybe_finish():
        if len(order) < args.frame:
            return
        for idx in range(args.frame - 1, len(order)):
            st = order[idx]
            if all(st in seen[k] for k in ("image", "depth", "detections")):
                write(idx, st)
                done.set()
                return

    def write(idx, st):
        img = to_array(seen["image"][st])
        cv2.imwrite(os.path.join(args.out, "frame_image.png"), img)
        cv2.imwrite(os.path.join(args.out, "frame_depth.png"), colour_depth(to_array(seen["depth"][st]), args.max_range))
        if args.boxes:
            det = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img.copy()
            for d in seen["detections"][st].detections:
                p0, p1 = (int(d.x_min), int(d.y_min)), (int(d.x_max), int(d.y_max))
                cv2.rectangle(det, p0, p1, (0, 255, 0), 2)
                cv2.putText(det, f"{d.class_name} {d.score:.2f}", (p0[0], max(12, p0[1] - 4)),
                            cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 255, 0), 1, cv2.LINE_AA)
        else:
            det = to_array(seen["detections"][st])
        cv2.imwrite(os.path.join(args.out, "frame_detections.png"), det)
        if st in seen["depth_masked"]:
            cv2.imwrite(os.path.join(args.out, "frame_depth_masked.png"), to_array(seen["depth_masked"][st]))
        with open(os.path.join(args.out, "frame.txt"), "w") as f:
            f.write(f"stamp: {st.to_sec():.6f}\nindex: {idx + 1}\nmax_range: {args.max_range}\n"
                    f"detections: {('boxes of ' + args.boxes) if args.boxes else topics['detections']}\n")

    def callback(key):
        def cb(msg):
            if done.is_set():
                return
            with lock:
                st = msg.header.stamp
                seen[key][st] = msg
                if key == "image":
                    order.append(st)
                # keep memory bounded: the last 40 messages of each topic
                if len(seen[key]) > 40:
                    for old in sorted(seen[key])[:-40]:
                        del seen[key][old]
                maybe_finish()
        return cb

    import rosgraph
    import time
    deadline = time.time() + args.timeout
    while not rosgraph.is_master_online():   # the demo starts this with the launch
        if time.time() > deadline:
            sys.exit("grab_frame: no ROS master")
        time.sleep(1)
    rospy.init_node("grab_frame", anonymous=True, disable_signals=True)
    subs = [rospy.Subscriber(t, types[k], callback(k), queue_size=5, buff_size=2 ** 24) for k, t in topics.items()]
    ok = done.wait(args.timeout)
    for s in subs:
        s.unregister()
    if not ok:
        print(f"grab_frame: no complete frame {args.frame} within {args.timeout:.0f} s "
              f"({len(order)} reference images seen)", file=sys.stderr)
        sys.exit(1)
    print(open(os.path.join(args.out, "frame.txt")).read(), end="")


if __name__ == "__main__":
    main()
