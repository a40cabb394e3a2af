#!/usr/bin/env python3
"""Plots depth_eval's per-frame CSV: Fig. 3 (scales), Fig. 5 (filters), Fig. 6 (cameras)."""
import csv
import sys
from collections import defaultdict

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(csv_path, out_dir):
    rows = defaultdict(list)
    with open(csv_path) as f:
        for r in csv.DictReader(f):
            rows[r["config"]].append(r)
    figures = {
        "fig3_scales.png": (["full resolution", "half resolution", "multi-scale"], "median_m",
                            "Median absolute depth error per frame (no filters)"),
        "fig5_filters.png": (["multi-scale", "multi-scale + cost filter", "+ uniqueness filter", "+ consistency filter",
                              "+ texture filter"],
                             "median_m", "Median absolute error after each filter"),
        "fig5_filters_mean.png": (["multi-scale", "multi-scale + cost filter", "+ uniqueness filter",
                                   "+ consistency filter", "+ texture filter"], "mean_m", "Mean absolute error after each filter"),
        "fig6_cameras.png": (["3 outer cameras", "3 central cameras", "5 cameras"], "median_m",
                             "Median absolute error by camera set (multi-scale, filtered)"),
    }
    for name, (configs, field, title) in figures.items():
        plt.figure(figsize=(7, 4))
        for c in configs:
            pts = [(int(r["frame"]), float(r[field])) for r in rows.get(c, [])]
            if pts:
                plt.plot(*zip(*pts), marker="o", label=c)
        plt.xlabel("frame")
        plt.ylabel(field.replace("_m", "") + " abs. error [m]")
        plt.title(title)
        plt.grid(True, alpha=0.3)
        plt.legend()
        plt.tight_layout()
        plt.savefig(f"{out_dir}/{name}", dpi=100)
        plt.close()
    print(f"plots written to {out_dir}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
