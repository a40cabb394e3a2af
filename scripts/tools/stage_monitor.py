#!/usr/bin/env python3
"""Counts what each stage of vehicle.launch puts out, until the pipeline goes idle.

usage: stage_monitor.py --out SUMMARY.md [--idle S] [--timeout S] [--wait-first S]
                        [--until-file F] [--progress S]

Subscribes (as AnyMsg, nothing is deserialized) to the frame sets, depth,
detections, masked depth, mesh and cloud topics; stops when no message arrived
on any of them for --idle seconds (wall time) after the first one, or after
--timeout, or as soon as the file --until-file exists (the paced player's
summary); every --progress seconds it prints one line of counts; writes a
markdown table: messages per topic, output rate over the
active span, first and last stamp. Exit status 1 when nothing arrived.
"""
import argparse
import os
import sys
import time

import rospy
from rospy.msg import AnyMsg

TOPICS = [
    ("/cam0/image_raw", "reference images in"),
    ("/fisheye_mapping/frames", "sync: frame sets"),
    ("/fisheye_mapping/depth/image", "plane sweep: depth"),
    ("/fisheye_mapping/detections", "detector: detections"),
    ("/cam0/detections_gt", "ground-truth boxes (oracle)"),
    ("/fisheye_mapping/depth_masked/image", "mask: masked depth"),
    ("/fisheye_mapping/tsdf/mesh", "fusion: mesh updates"),
    ("/fisheye_mapping/tsdf/cloud", "fusion: cloud updates"),
    ("/fisheye_mapping/tsdf/fusion_done", "fusion: depth frames finished"),
]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--idle", type=float, default=20.0)
    ap.add_argument("--timeout", type=float, default=1800.0)
    ap.add_argument("--wait-first", type=float, default=120.0)
    ap.add_argument("--until-file", default="")
    ap.add_argument("--progress", type=float, default=0.0)
    args = ap.parse_args(rospy.myargv()[1:])
    rospy.init_node("stage_monitor", anonymous=True, disable_signals=True)
    stats = {t: {"n": 0, "first": None, "last": None} for t, _ in TOPICS}

    def cb(msg, topic):
        s = stats[topic]
        now = time.time()
        s["n"] += 1
        s["first"] = s["first"] or now
        s["last"] = now

    subs = [rospy.Subscriber(t, AnyMsg, cb, callback_args=t, queue_size=50) for t, _ in TOPICS]
    start = time.time()
    last_progress = start
    while True:
        time.sleep(0.5)
        now = time.time()
        if args.until_file and os.path.exists(args.until_file):
            break
        if args.progress > 0 and now - last_progress >= args.progress:
            last_progress = now
            print(f"[{now - start:5.0f} s] frame sets {stats['/fisheye_mapping/frames']['n']}, depth {stats['/fisheye_mapping/depth/image']['n']}, "
                  f"masked {stats['/fisheye_mapping/depth_masked/image']['n']}, fused {stats['/fisheye_mapping/tsdf/fusion_done']['n']}", flush=True)
        lasts = [s["last"] for s in stats.values() if s["last"]]
        if not lasts and now - start > args.wait_first:
            break
        if lasts and now - max(lasts) > args.idle:
            break
        if now - start > args.timeout:
            break
    for s in subs:
        s.unregister()
    lines = ["| stage | topic | messages | rate (Hz, over its active span) |", "|---|---|---:|---:|"]
    for t, what in TOPICS:
        s = stats[t]
        span = (s["last"] - s["first"]) if s["n"] > 1 else 0.0
        rate = f"{(s['n'] - 1) / span:.2f}" if span > 0 else "-"
        lines.append(f"| {what} | `{t}` | {s['n']} | {rate} |")
    text = "\n".join(lines) + "\n"
    with open(args.out, "w") as f:
        f.write(text)
    print(text)
    return 0 if any(s["n"] for s in stats.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
