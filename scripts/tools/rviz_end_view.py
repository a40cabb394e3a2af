#!/usr/bin/env python3
"""Writes an rviz config whose view looks back over the whole map: a copy of
rviz/vehicle_end.rviz (an Orbit view in the map frame) with the focal point at
the middle of the map, the eye above and beyond the car's last position (the
end of the drive), looking back towards the start, far enough to see it all.

usage: rviz_end_view.py --cloud cloud.pcd --template rviz/vehicle_end.rviz --out OUT.rviz
                        [--end X,Y] [--tf map,base_link] [--pitch 0.8]

--end   the car's last position in the map frame; --tf looks it up from tf
        instead (a running ROS master, e.g. the demo's paced player holding
        the last pose); without either, the eye is on the map's main axis
        (either end).
Prints the view it wrote.
"""
import argparse
import math
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from topdown_png import read_pcd  # noqa: E402


def lookup_end(frames, timeout=10.0):
    try:
        import rospy
        import tf2_ros
    except ImportError:
        return None
    world, base = frames.split(",")
    import time
    rospy.init_node("rviz_end_view", anonymous=True, disable_signals=True)
    buf = tf2_ros.Buffer()
    tf2_ros.TransformListener(buf)
    # Wall-clock deadline: under use_sim_time the clock stops with the drive,
    # so a ROS-time timeout would never expire.
    deadline = time.time() + timeout
    t = None
    while time.time() < deadline:
        try:
            t = buf.lookup_transform(world, base, rospy.Time(0))
            break
        except Exception:  # noqa: BLE001 (not there yet)
            time.sleep(0.2)
    if t is None:
        print(f"rviz_end_view: no {world} -> {base} transform within {timeout:.0f} s; eye on the map's axis",
              file=sys.stderr)
        return None
    return np.array([t.transform.translation.x, t.transform.translation.y])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cloud", required=True)
    ap.add_argument("--template", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--end")
    ap.add_argument("--tf")
    ap.add_argument("--pitch", type=float, default=0.8)
    args = ap.parse_args()
    pts = read_pcd(args.cloud)
    pts = pts[np.isfinite(pts).all(1)]
    if len(pts) == 0:
        sys.exit(f"{args.cloud}: no points")
    xy = pts[:, :2].astype(np.float64)
    lo, hi = np.percentile(xy, 1, axis=0), np.percentile(xy, 99, axis=0)
    centre = (lo + hi) / 2
    ground = float(np.percentile(pts[:, 2], 10))
    end = None
    if args.end:
        end = np.array([float(v) for v in args.end.split(",")])
    elif args.tf:
        end = lookup_end(args.tf)
    d = xy[:: max(1, len(xy) // 200000)] - centre
    w, vecs = np.linalg.eigh(np.cov(d.T))
    axis = vecs[:, np.argmax(w)]
    if end is not None and np.linalg.norm(end - centre) > 1.0:
        axis = (end - centre) / np.linalg.norm(end - centre)
    proj = d @ axis
    length = float(np.percentile(proj, 99) - np.percentile(proj, 1))
    side = float(np.percentile(np.abs(d @ np.array([-axis[1], axis[0]])), 99))
    # distance so that the map's length fits the 0.785 rad field of view, seen at the pitch
    span = max(length, 1.6 * 2 * side, 20.0)
    # (seen at the pitch, the length is foreshortened: 0.65 of the distance that fits it face-on)
    distance = 0.5 * span / math.tan(0.785 / 2) * 0.65
    # a little to one side of the axis, so that the facades of one side are seen at an angle
    yaw = math.atan2(axis[1], axis[0]) + 0.45
    s = open(args.template).read()
    view = s[s.index("    Current:\n"):s.index("    Saved:")]
    new = view
    new = re.sub(r"(      Distance: ).*", lambda m: f"{m.group(1)}{distance:.1f}", new, count=1)
    new = re.sub(r"(      Focal Point:\n        X: ).*\n(        Y: ).*\n(        Z: ).*",
                 lambda m: f"{m.group(1)}{centre[0]:.2f}\n{m.group(2)}{centre[1]:.2f}\n{m.group(3)}{ground:.2f}", new, count=1)
    new = re.sub(r"(      Pitch: ).*", lambda m: f"{m.group(1)}{args.pitch:.3f}", new, count=1)
    new = re.sub(r"(      Yaw: ).*", lambda m: f"{m.group(1)}{yaw:.4f}", new, count=1)
    open(args.out, "w").write(s.replace(view, new))
    print(f"rviz_end_view: focal point ({centre[0]:.1f}, {centre[1]:.1f}, {ground:.1f}), yaw {yaw:.2f} rad, "
          f"pitch {args.pitch:.2f} rad, distance {distance:.0f} m (map {length:.0f} m long, "
          f"end {'from ' + ('--end' if args.end else 'tf') if end is not None else 'unknown'})")


if __name__ == "__main__":
    main()
    sys.stdout.flush()
    os._exit(0)   # rospy's threads (with --tf) would keep the process alive
