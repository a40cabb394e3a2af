"""Where the reference map's points that our map misses are (issue 31).

    /usr/bin/python3 scripts/eval/missing_points.py MAP_DIR REF_DIR DRIVE_BAG

MAP_DIR, REF_DIR: offline_mapper outputs (cloud.pcd: with the minimum-
observation filter, cloud_all.pcd: without); DRIVE_BAG: the drive (its /tf
gives the path). A reference point is missing when no point of our cloud lies
within 0.25 m (completeness's tolerance); it was rejected by the observation
rule when our cloud_all has a point within 0.25 m. Printed by road (< 0.3 m
above z = 0) and structure, and by lateral distance from the driven path.
"""
import os
import sys

import numpy as np
import rosbag
from scipy.spatial import cKDTree

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))
from topdown_png import read_pcd as pcd  # noqa: E402


def main():
    ours_dir, ref_dir, bag = sys.argv[1:4]
    ref = pcd(ref_dir + "/cloud.pcd")
    ours = pcd(ours_dir + "/cloud.pcd")
    every = pcd(ours_dir + "/cloud_all.pcd")
    path = []
    for _, msg, _ in rosbag.Bag(bag).read_messages(topics=["/tf"]):
        for tr in msg.transforms:
            if tr.child_frame_id == "base_link":
                path.append([tr.transform.translation.x, tr.transform.translation.y])
    path = np.array(path)
    d, _ = cKDTree(ours).query(ref, distance_upper_bound=0.25)
    miss = ~np.isfinite(d)
    d_all, _ = cKDTree(every).query(ref, distance_upper_bound=0.25)
    seen = np.isfinite(d_all)
    lateral, _ = cKDTree(path).query(ref[:, :2])
    high = ref[:, 2] >= 0.3
    print(f"reference points {len(ref)}, missing {miss.sum()} ({100 * miss.mean():.1f} %)")
    print("| part | lateral from the path | reference points | missing | of them: observed, rejected by the observation rule | never observed |")
    print("|---|---|---:|---:|---:|---:|")
    for name, sel in (("road (< 0.3 m)", ~high), ("structure (>= 0.3 m)", high)):
        for lo, hi in ((0, 4), (4, 8), (8, 12), (12, 1e9)):
            s = sel & (lateral >= lo) & (lateral < hi)
            m = miss & s
            k = max(1, m.sum())
            band = f"{lo}-{hi:g} m" if hi < 1e9 else f">= {lo} m"
            print(f"| {name} | {band} | {s.sum()} | {100 * m.sum() / max(1, s.sum()):.1f} % | "
                  f"{100 * (m & seen).sum() / k:.1f} % | {100 * (m & ~seen).sum() / k:.1f} % |")


if __name__ == "__main__":
    main()
