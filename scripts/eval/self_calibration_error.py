#!/usr/bin/env python3
"""Rotation (and translation) error of the online self-calibration over a drive, per camera:
offline_mapper's self_calibration.csv (each supporting camera's rotation
relative to cam0 after each update) against the drive's true calibration
(camchain_true.yaml, or camchain.yaml for an exact drive; after a
make_drive --knock, camchain_knocked.yaml from the knock on: knock.yaml).

usage: self_calibration_error.py DRIVE_DIR SELF_CALIBRATION_CSV   (markdown on stdout)

Prints the error as given, at the first update, after 10 s of drive, 3 s
after the knock (if any) and at the end, in degrees; drive time 0 is the
first update's stamp (the first frame set). When the CSV has the
translations (t_ref_cam_*_m), a second table gives the translation error
(mm) at the same times.
"""
import csv
import os
import sys

import numpy as np
import yaml

from compare_calibration import chain


def rotvec_to_matrix(w_deg):
    w = np.radians(np.asarray(w_deg, dtype=float))
    a = np.linalg.norm(w)
    if a < 1e-15:
        return np.eye(3)
    k = w / a
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def angle_deg(R):
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))


def rel_rotations(path):
    """R_cam0_cam of every camera of a camchain."""
    return {cam: np.linalg.inv(T)[:3, :3] for cam, T in chain(path).items()}


def rel_translations(path):
    """t_cam0_cam of every camera of a camchain (metres)."""
    return {cam: np.linalg.inv(T)[:3, 3] for cam, T in chain(path).items()}


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__.strip())
    drive, csv_path = sys.argv[1], sys.argv[2]
    true_path = os.path.join(drive, "camchain_true.yaml")
    if not os.path.exists(true_path):
        true_path = os.path.join(drive, "camchain.yaml")
    truth = rel_rotations(true_path)
    given = rel_rotations(os.path.join(drive, "camchain.yaml"))
    knock = None
    if os.path.exists(os.path.join(drive, "knock.yaml")):
        with open(os.path.join(drive, "knock.yaml")) as f:
            knock = yaml.safe_load(f)
        knocked = rel_rotations(os.path.join(drive, "camchain_knocked.yaml"))
    true_t = rel_translations(true_path)
    given_t = rel_translations(os.path.join(drive, "camchain.yaml"))
    if knock:
        knocked_t = rel_translations(os.path.join(drive, "camchain_knocked.yaml"))
    rows = list(csv.DictReader(open(csv_path)))
    has_t = bool(rows) and "t_ref_cam_x_m" in rows[0]
    if not rows:
        sys.exit(f"{csv_path}: no update")
    t0 = float(rows[0]["stamp"])
    series = {}
    t_series = {}
    for r in rows:
        t = float(r["stamp"]) - t0
        cam = r["camera"]
        R = rotvec_to_matrix([r["rotvec_ref_cam_x_deg"], r["rotvec_ref_cam_y_deg"], r["rotvec_ref_cam_z_deg"]])
        ref = knocked if knock and t >= float(knock["at_s"]) else truth
        series.setdefault(cam, []).append((t, angle_deg(ref[cam].T @ R), r["level"]))
        if has_t:
            ref_t = knocked_t if knock and t >= float(knock["at_s"]) else true_t
            tv = np.array([float(r["t_ref_cam_x_m"]), float(r["t_ref_cam_y_m"]), float(r["t_ref_cam_z_m"])])
            t_series.setdefault(cam, []).append((t, 1000 * float(np.linalg.norm(tv - ref_t[cam])), r["level"]))

    def at(s, t):
        """Error at the last update at or before drive time t."""
        before = [e for (tt, e, _) in s if tt <= t + 1e-6]
        return before[-1] if before else float("nan")

    marks = [("first update", 0.0), ("10 s", 10.0)]
    if knock:
        marks.append((f"knock + 3 s ({knock['at_s'] + 3:g} s)", float(knock["at_s"]) + 3.0))
    end = max(t for s in series.values() for (t, _, _) in s)
    marks.append((f"end ({end:.1f} s)", end))
    def table(errors, given_error, digits):
        print("| camera | given | " + " | ".join(m for m, _ in marks) + " |")
        print("|---|---:|" + "---:|" * len(marks))
        for cam in sorted(errors):
            cells = [f"{given_error(cam):.{digits}f}"] + [f"{at(errors[cam], t):.{digits}f}" for _, t in marks]
            print(f"| {cam} | " + " | ".join(cells) + " |")

    table(series, lambda cam: angle_deg(truth[cam].T @ given[cam]), 3)
    if has_t:
        print("\nTranslation error (mm):\n")
        table(t_series, lambda cam: 1000 * np.linalg.norm(given_t[cam] - true_t[cam]), 1)
    if knock:
        print(f"\n{knock['camera']} knocked by {knock['deg']:g} deg at {knock['at_s']:g} s "
              f"(errors from then on against camchain_knocked.yaml).")


if __name__ == "__main__":
    main()
