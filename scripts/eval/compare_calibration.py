#!/usr/bin/env python3
"""Calibration error of Kalibr camchains against the true one, per camera:
the rotation angle and translation of T_cam0_cam relative to the truth.

usage: compare_calibration.py TRUE.yaml GIVEN.yaml [REFINED.yaml]   (markdown table on stdout)
"""
import sys

import numpy as np
import yaml


def chain(path):
    """T_ci_c0 of every camera of a camchain (T_cn_cnm1 composed)."""
    with open(path) as f:
        doc = yaml.safe_load(f)
    names = sorted((k for k in doc if k.startswith("cam") and k[3:].isdigit()), key=lambda s: int(s[3:]))
    T, prev = {}, np.eye(4)
    for i, name in enumerate(names):
        if i > 0:
            prev = np.array(doc[name]["T_cn_cnm1"], dtype=float) @ prev
        T[name] = prev.copy()
    return T


def error(truth, other):
    d = truth @ np.linalg.inv(other)
    angle = np.degrees(np.arccos(np.clip((np.trace(d[:3, :3]) - 1) / 2, -1.0, 1.0)))
    return angle, 1000 * np.linalg.norm(d[:3, 3])


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__.strip())
    truth = chain(sys.argv[1])
    others = [("given", chain(sys.argv[2]))]
    if len(sys.argv) == 4:
        try:
            others.append(("refined", chain(sys.argv[3])))
        except OSError:
            pass  # refine_rig wrote nothing (it says why in its log)
    head = " | ".join(f"{n} rotation [deg] | {n} translation [mm]" for n, _ in others)
    print(f"| camera | {head} |")
    print("|---|" + "---:|---:|" * len(others))
    for cam in list(truth)[1:]:
        cells = []
        for _, T in others:
            r, t = error(truth[cam], T[cam]) if cam in T else (float("nan"), float("nan"))
            cells += [f"{r:.3f}", f"{t:.1f}"]
        print(f"| {cam} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
