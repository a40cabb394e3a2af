#!/usr/bin/env python3
"""Top-down picture of a map cloud (PCD, ASCII or binary, fields x y z first
among float32 fields), coloured by height, with a metre scale bar and a
colour legend.

usage: topdown_png.py CLOUD.pcd OUT.png [--resolution M] [--title TEXT]

Each pixel shows the highest point that falls in it (x to the right, y up, as
seen from above in the map frame). Exit status 1 on an unreadable or empty
cloud, with the reason.
"""
import argparse
import sys

import numpy as np


def read_pcd(path):
    with open(path, "rb") as f:
        header = {}
        while True:
            line = f.readline()
            if not line:
                raise ValueError("no DATA line: not a PCD file")
            key, _, value = line.decode("ascii", "replace").strip().partition(" ")
            if key.startswith("#") or not key:
                continue
            header[key] = value.split()
            if key == "DATA":
                break
        fields = header.get("FIELDS", [])
        sizes = [int(s) for s in header.get("SIZE", [])]
        types = header.get("TYPE", [])
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(fields))]
        points = int(header.get("POINTS", ["0"])[0])
        if not all(k in fields for k in ("x", "y", "z")):
            raise ValueError(f"fields {fields} lack x, y, z")
        if points == 0:
            return np.zeros((0, 3), np.float32)
        mode = header["DATA"][0]
        if mode == "ascii":
            data = np.loadtxt(f, dtype=np.float64, ndmin=2)
            cols = [sum(counts[: fields.index(k)]) for k in ("x", "y", "z")]
            return data[:, cols].astype(np.float32)
        if mode != "binary":
            raise ValueError(f"DATA {mode} is not supported (ascii or binary)")
        dt = []
        for name, size, typ, count in zip(fields, sizes, types, counts):
            base = {("F", 4): "<f4", ("F", 8): "<f8", ("U", 1): "u1", ("U", 2): "<u2", ("U", 4): "<u4",
                    ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4"}[(typ, size)]
            dt.append((name if name != "_" else f"pad{len(dt)}", base, (count,)) if count > 1 else
                      (name if name != "_" else f"pad{len(dt)}", base))
        raw = np.frombuffer(f.read(), dtype=np.dtype(dt), count=points)
        return np.stack([raw["x"], raw["y"], raw["z"]], axis=1).astype(np.float32)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("cloud")
    ap.add_argument("out")
    ap.add_argument("--resolution", type=float, default=0.1, help="metres per pixel")
    ap.add_argument("--title", default="")
    args = ap.parse_args()
    try:
        pts = read_pcd(args.cloud)
    except (OSError, ValueError, KeyError) as e:
        print(f"topdown_png: {args.cloud}: {e}", file=sys.stderr)
        return 1
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) == 0:
        print(f"topdown_png: {args.cloud}: no points", file=sys.stderr)
        return 1
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    res = args.resolution
    lo = pts[:, :2].min(axis=0) - 1.0
    hi = pts[:, :2].max(axis=0) + 1.0
    size = np.ceil((hi - lo) / res).astype(int) + 1
    ix = ((pts[:, 0] - lo[0]) / res).astype(int)
    iy = ((pts[:, 1] - lo[1]) / res).astype(int)
    height = np.full((size[1], size[0]), np.nan, np.float32)
    order = np.argsort(pts[:, 2])  # the highest point of a cell is written last
    height[iy[order], ix[order]] = pts[order, 2]
    zlo, zhi = np.percentile(pts[:, 2], [2, 98])
    fig, ax = plt.subplots(figsize=(10, 10 * size[1] / max(size[0], 1) + 1), dpi=100)
    ax.set_facecolor("black")
    im = ax.imshow(height, origin="lower", cmap="turbo", vmin=zlo, vmax=max(zhi, zlo + 0.1),
                   extent=[lo[0], lo[0] + size[0] * res, lo[1], lo[1] + size[1] * res], interpolation="nearest")
    ax.set_xlabel("x [m] (map frame)")
    ax.set_ylabel("y [m]")
    ax.set_title(args.title or f"{len(pts)} points, top-down, coloured by height")
    fig.colorbar(im, ax=ax, label="height z [m]", shrink=0.8)
    fig.tight_layout()
    fig.savefig(args.out)
    print(f"topdown_png: {args.out} ({len(pts)} points, {size[0]}x{size[1]} cells of {res} m)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
