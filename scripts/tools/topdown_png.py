#!/usr/bin/env python3
"""Top-down picture of a map cloud (PCD, ASCII or binary, fields x y z first
among float32 fields), coloured by the map's intensity (the grey of the images
fused into the voxels: the cloud's `intensity` field, 0 = none) or by height,
with a metre scale and a colour legend.

usage: topdown_png.py CLOUD.pcd OUT.png [--resolution M] [--title TEXT] [--colour intensity|height]

Each pixel shows the highest point that falls in it (x to the right, y up, as
seen from above in the map frame). --colour intensity (the default when the
cloud has intensities) draws points without one in dark blue. Exit status 1 on
an unreadable or empty cloud, with the reason.
"""
import argparse
import sys

import numpy as np


def read_pcd(path, intensity=False):
    """x y z of every point (N x 3); with intensity=True N x 4, the 4th column
    the `intensity` field (NaN when the cloud has none)."""
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
            return np.zeros((0, 4 if intensity else 3), np.float32)
        want = ("x", "y", "z", "intensity") if intensity and "intensity" in fields else ("x", "y", "z")
        mode = header["DATA"][0]
        if mode == "ascii":
            data = np.loadtxt(f, dtype=np.float64, ndmin=2)
            cols = [sum(counts[: fields.index(k)]) for k in want]
            out = data[:, cols].astype(np.float32)
        else:
            out = None
        if out is not None:
            pass
        elif mode != "binary":
            raise ValueError(f"DATA {mode} is not supported (ascii or binary)")
        dt = []
        for name, size, typ, count in zip(fields, sizes, types, counts):
            base = {("F", 4): "<f4", ("F", 8): "<f8", ("U", 1): "u1", ("U", 2): "<u2", ("U", 4): "<u4",
                    ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4"}[(typ, size)]
            dt.append((name if name != "_" else f"pad{len(dt)}", base, (count,)) if count > 1 else
                      (name if name != "_" else f"pad{len(dt)}", base))
        if out is None:
            raw = np.frombuffer(f.read(), dtype=np.dtype(dt), count=points)
            out = np.stack([raw[k] for k in want], axis=1).astype(np.float32)
        if intensity and out.shape[1] == 3:
            out = np.concatenate([out, np.full((len(out), 1), np.nan, np.float32)], axis=1)
        return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("cloud")
    ap.add_argument("out")
    ap.add_argument("--resolution", type=float, default=0.1, help="metres per pixel")
    ap.add_argument("--title", default="")
    ap.add_argument("--colour", choices=("intensity", "height"), default=None,
                    help="default: intensity when the cloud has it, else height")
    args = ap.parse_args()
    try:
        pts = read_pcd(args.cloud, intensity=True)
    except (OSError, ValueError, KeyError) as e:
        print(f"topdown_png: {args.cloud}: {e}", file=sys.stderr)
        return 1
    pts = pts[np.isfinite(pts[:, :3]).all(axis=1)]
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
    grey = pts[:, 3]
    has_grey = bool(np.any(grey > 0))
    colour = args.colour or ("intensity" if has_grey else "height")
    order = np.argsort(pts[:, 2])  # the highest point of a cell is written last
    extent = [lo[0], lo[0] + size[0] * res, lo[1], lo[1] + size[1] * res]
    fig, ax = plt.subplots(figsize=(10, 10 * size[1] / max(size[0], 1) + 1), dpi=100)
    ax.set_facecolor("black")
    if colour == "intensity":
        rgb = np.zeros((size[1], size[0], 3), np.float32)
        g = np.where(grey[order] > 0, grey[order] / 255.0, np.nan)
        cell = np.stack([g, g, g], axis=1)
        cell[~np.isfinite(g)] = (0.1, 0.15, 0.45)  # no intensity: dark blue
        rgb[iy[order], ix[order]] = cell
        ax.imshow(rgb, origin="lower", extent=extent, interpolation="nearest")
        what = "intensity (grey of the fused images)"
    else:
        height = np.full((size[1], size[0]), np.nan, np.float32)
        height[iy[order], ix[order]] = pts[order, 2]
        zlo, zhi = np.percentile(pts[:, 2], [2, 98])
        im = ax.imshow(height, origin="lower", cmap="turbo", vmin=zlo, vmax=max(zhi, zlo + 0.1),
                       extent=extent, interpolation="nearest")
        fig.colorbar(im, ax=ax, label="height z [m]", shrink=0.8)
        what = "height"
    ax.set_xlabel("x [m] (map frame)")
    ax.set_ylabel("y [m]")
    ax.set_title(args.title or f"{len(pts)} points, top-down, coloured by {what}")
    fig.tight_layout()
    fig.savefig(args.out)
    print(f"topdown_png: {args.out} ({len(pts)} points, {size[0]}x{size[1]} cells of {res} m)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
