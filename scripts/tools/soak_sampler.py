#!/usr/bin/env python3
"""Samples a running vehicle.launch once a period for scripts/checks/soak.

usage: soak_sampler.py --csv SAMPLES.csv [--period S] [--until-file F] [--timeout S]
                       [--process NAME ...] [--viewer TOPIC ...]

Each --period seconds of wall time (default 60) it writes one row to --csv:
the resident memory (VmRSS, MB) of each --process (a ROS node name such as
depth_manager, found by its __name:= argument in /proc/*/cmdline), read every
--rss-every seconds (default 5): the median and the maximum of the period's
readings (a map's cloud and mesh messages come and go each publish period;
the median is what stays), with its pid ("gone" when it exited, two pids
when it was respawned within the period), and, from
/diagnostics, per stage (the status name's last part: sync, depth, detector,
depth_mask, tsdf) its inputs, outputs, the total of its dropped counts and
its backlog (inputs - outputs - dropped: what it holds in its queues or
mailbox; only for depth, detector and tsdf: the sync takes images and gives
frame sets, the mask's drops count detection sets too),
plus the TSDF map's blocks in memory, its mesh's triangles and the memory
the map itself holds (voxels, mesh). Meanwhile it
subscribes to each --viewer topic (none by default; scripts/checks/soak
--viewer gives the mesh, the cloud and the masked depth, as rviz takes
them; nothing is deserialized), so that the stages build all they build for
a user watching. It stops with a last row as soon
as the file --until-file exists (the paced player's summary), or after
--timeout seconds. Exit status 1 when no diagnostics arrived.
"""
import argparse
import csv
import os
import re
import sys
import threading
import time

import rospy
from diagnostic_msgs.msg import DiagnosticArray
from rospy.msg import AnyMsg

STAGES = ["sync", "depth", "detector", "depth_mask", "tsdf"]


def find_pid(name):
    """The pid of the process started with __name:=NAME, or None."""
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                args = f.read().split(b"\0")
        except OSError:
            continue
        if f"__name:={name}".encode() in args:
            return int(pid)
    return None


def rss_mb(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def total(value):
    """A diagnostics count: a number, or "<n> in the last <w> s, <total> total"."""
    m = re.search(r"(\d+) total$", value)
    if m:
        return int(m.group(1))
    try:
        return int(float(value))
    except ValueError:
        return None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--csv", required=True)
    ap.add_argument("--period", type=float, default=60.0)
    ap.add_argument("--rss-every", type=float, default=5.0)
    ap.add_argument("--until-file", default="")
    ap.add_argument("--timeout", type=float, default=86400.0)
    ap.add_argument("--viewer", nargs="*", default=[])
    ap.add_argument("--process", nargs="*", default=["depth_manager", "detection_manager", "fusion_manager", "player"])
    args = ap.parse_args(rospy.myargv()[1:])
    rospy.init_node("soak_sampler", anonymous=True, disable_signals=True)
    lock = threading.Lock()
    stages = {}  # stage -> {key: value}

    def on_diagnostics(msg):
        with lock:
            for st in msg.status:
                stage = st.name.split(": ")[-1]
                if stage in STAGES:
                    stages[stage] = {kv.key: kv.value for kv in st.values}

    rospy.Subscriber("/diagnostics", DiagnosticArray, on_diagnostics, queue_size=50)
    # A viewer's subscriptions (rviz's: the mesh, the cloud, the depth image),
    # so that the stages do all they do for a user watching the map.
    viewer = [rospy.Subscriber(t, AnyMsg, lambda _: None, queue_size=2) for t in args.viewer]
    header = ["minute", "wall_s"]
    for p in args.process:
        header += [f"{p}_pid", f"{p}_rss_mb", f"{p}_rss_max_mb"]
    for s in STAGES:
        header += [f"{s}_inputs", f"{s}_outputs", f"{s}_dropped", f"{s}_backlog"]
    header += ["tsdf_blocks", "tsdf_mesh_triangles", "tsdf_voxel_mb", "tsdf_mesh_mb"]
    start = time.time()
    rows = 0
    with open(args.csv, "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(header)
        f.flush()
        next_sample = start + args.period
        next_rss = start
        rss_seen = {p: [] for p in args.process}  # this period's readings: (pid, MB or None)
        started = set()  # processes seen running: before that, no reading is "gone"
        while True:
            done = bool(args.until_file) and os.path.exists(args.until_file)
            now = time.time()
            if now >= next_rss and not done:  # memory every --rss-every s: a row has its median and maximum
                next_rss += args.rss_every
                for p in args.process:
                    pid = find_pid(p)
                    rss = rss_mb(pid) if pid else None
                    if rss is not None:
                        started.add(p)
                    if rss is not None or p in started:
                        rss_seen[p].append((pid if rss is not None else None, rss))
            if not done and now < next_sample and now - start < args.timeout:
                time.sleep(0.5)
                continue
            next_sample += args.period
            if done and not any(rss_seen.values()):
                break  # the drive ended with the last row (the launch goes down after it)
            row = [f"{(now - start) / 60.0:.2f}", f"{now - start:.0f}"]
            for p in args.process:
                seen, rss_seen[p] = rss_seen[p], []
                pids = {pid for pid, _ in seen}
                values = sorted(v for _, v in seen if v is not None)
                if not seen:  # not started yet
                    row += ["", "", ""]
                elif not values or None in pids or len(pids) > 1:  # exited or respawned within the period
                    row += ["gone" if None in pids or not values else "+".join(str(x) for x in sorted(pids)),
                            "gone", "gone"]
                else:
                    row += [pids.pop(), f"{values[len(values) // 2]:.1f}", f"{values[-1]:.1f}"]
            with lock:
                snapshot = {k: dict(v) for k, v in stages.items()}
            for s in STAGES:
                v = snapshot.get(s, {})
                inputs, outputs = total(v.get("inputs", "")), total(v.get("outputs", ""))
                dropped = sum(total(val) or 0 for key, val in v.items() if key.startswith("dropped: "))
                # Not for the sync (images in, frame sets out) nor the mask (its drops count
                # detection sets too, and depth passed unmasked is an output as well).
                same_unit = s in ("depth", "detector", "tsdf") and inputs is not None and outputs is not None
                backlog = inputs - outputs - dropped if same_unit else ""
                row += ["" if inputs is None else inputs, "" if outputs is None else outputs,
                        dropped if v else "", backlog]
            tsdf = snapshot.get("tsdf", {})
            row += [tsdf.get(k, "") for k in ["blocks", "mesh triangles", "voxel memory (MB)", "mesh memory (MB)"]]
            out.writerow(row)
            f.flush()
            rows += 1
            print(f"[{row[0]} min] " + ", ".join(
                f"{p} {row[2 + 3 * i + 1]} MB" for i, p in enumerate(args.process)), flush=True)
            if done or now - start >= args.timeout:
                break
    return 0 if stages else 1


if __name__ == "__main__":
    sys.exit(main())
