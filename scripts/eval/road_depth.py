#!/usr/bin/env python3
"""Road depth of the reference camera against a synthetic drive's ground truth,
and what a flat ground plane taken from the mount alone would give (the
measure of issue 26's held-out real rig: median relative error of the road
within 20 m).

usage: road_depth.py DRIVE_DIR DEPTH_DIR [DEPTH_DIR ...]   (markdown on stdout)

DRIVE_DIR: a make_drive output (drive.bag with /cam0/depth_gt, camchain.yaml,
mount.yaml). DEPTH_DIR: depth maps of that bag's frame sets, as
plane_sweep_depth --bag writes them (depth_<stamp>.tiff, 32-bit float range
along the ray, NaN invalid). A road pixel is one whose true point lies within
3 cm of the base frame's ground plane (z = 0), from the true range along the
pixel's ray (camera model of camchain.yaml's cam0: Kalibr omni + radtan, or
pinhole + radtan; the reference camera's calibration is exact in make_drive's
drives, only the supporting cameras' is perturbed). Per DEPTH_DIR: the road
pixels within 20 m with a depth (coverage), the median relative error of
those and its signed median, then the same per range band. The flat-ground
guess is the range at which each road pixel's ray meets z = 0 of the mount: on
a synthetic drive's flat road it is exact, so it is printed only as the check
of the road selection (0 %).
"""
import glob
import os
import sys

import cv2
import numpy as np
import rosbag
import yaml

BANDS = [(0.0, 1.5), (1.5, 4.0), (4.0, 8.0), (8.0, 12.0), (12.0, 16.0), (16.0, 20.0), (20.0, 30.0)]


def rays_of(cam):
    """Unit rays (H x W x 3, NaN where none) of a Kalibr camchain camera."""
    model = cam['camera_model']
    w, h = cam['resolution']
    if model == 'omni':
        xi, fu, fv, pu, pv = cam['intrinsics']
    elif model == 'pinhole':
        xi = 0.0
        fu, fv, pu, pv = cam['intrinsics']
    else:
        sys.exit(f"road_depth.py: camera model '{model}' is not supported (omni, pinhole)")
    if cam.get('distortion_model', 'radtan') not in ('radtan', 'none'):
        sys.exit(f"road_depth.py: distortion model '{cam['distortion_model']}' is not supported (radtan)")
    k1, k2, p1, p2 = (list(cam.get('distortion_coeffs', [])) + [0.0] * 4)[:4]
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    xd, yd = (u - pu) / fu, (v - pv) / fv
    x, y = xd.copy(), yd.copy()
    for _ in range(20):  # radtan inverted by fixed-point iteration
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        x, y = (xd - dx) / radial, (yd - dy) / radial
    r2 = x * x + y * y
    disc = 1 + (1 - xi * xi) * r2
    with np.errstate(invalid='ignore'):
        f = (xi + np.sqrt(disc)) / (r2 + 1)
    ray = np.stack([f * x, f * y, f - xi], -1)
    ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
    ray[~(disc > 0)] = np.nan
    return ray


def stamp_key(sec, nsec):
    return sec + nsec * 1e-9


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    drive = sys.argv[1]
    truth = {}
    with rosbag.Bag(os.path.join(drive, 'drive.bag')) as bag:
        for _, m, _ in bag.read_messages(topics=['/cam0/depth_gt']):
            if m.encoding != '32FC1':
                sys.exit(f"road_depth.py: /cam0/depth_gt is {m.encoding}, 32FC1 expected")
            truth[stamp_key(m.header.stamp.secs, m.header.stamp.nsecs)] = np.frombuffer(
                m.data, dtype=np.float32).reshape(m.height, m.width)
    if not truth:
        sys.exit(f"road_depth.py: {drive}/drive.bag has no /cam0/depth_gt (make_drive --gt-depth ref)")
    T = np.array(yaml.safe_load(open(os.path.join(drive, 'mount.yaml')))['T_base_cam0'], dtype=float)
    ray = rays_of(yaml.safe_load(open(os.path.join(drive, 'camchain.yaml')))['cam0'])
    R, t = T[:3, :3], T[:3, 3]
    down = -(ray @ R[2])  # ray's downward component in the base frame
    with np.errstate(invalid='ignore', divide='ignore'):
        flat = np.where(down > 1e-3, t[2] / down, np.nan)
    print('| depth | road pixels within 20 m | with a depth | median relative error | signed | '
          + ' | '.join(f'{lo:g}-{hi:g} m' for lo, hi in BANDS) + ' |')
    print('|---|---:|---:|---:|---:|' + '---:|' * len(BANDS))
    for d in sys.argv[2:]:
        files = sorted(glob.glob(os.path.join(d, 'depth_*.tiff')))
        if not files:
            sys.exit(f"road_depth.py: no depth_*.tiff in {d}")
        est, tru, prior = [], [], []
        for f in files:
            s = float(os.path.basename(f)[len('depth_'):-len('.tiff')])
            key = min(truth, key=lambda k: abs(k - s))
            if abs(key - s) > 1e-3:
                continue
            g = truth[key]
            e = cv2.imread(f, cv2.IMREAD_UNCHANGED)
            if e is None or e.shape != g.shape:
                sys.exit(f"road_depth.py: {f} is not a depth map of the reference's size {g.shape[::-1]}")
            z = (g[..., None] * ray) @ R[2] + t[2]
            road = np.isfinite(g) & np.isfinite(z) & (np.abs(z) < 0.03) & (g <= BANDS[-1][1])
            est.append(e[road])
            tru.append(g[road])
            prior.append(flat[road])
        if not tru:
            sys.exit(f"road_depth.py: no depth map in {d} has a stamp of the bag's ground truth")
        e, g, p = np.concatenate(est), np.concatenate(tru), np.concatenate(prior)

        def figures(mask):
            ok = mask & np.isfinite(e)
            rel = (e[ok] - g[ok]) / g[ok]
            if not ok.any():
                return 0, ok.sum(), float('nan'), float('nan')
            return mask.sum(), ok.sum(), 100 * np.median(np.abs(rel)), 100 * np.median(rel)

        n, k, med, signed = figures(g <= 20.0)
        bands = []
        for lo, hi in BANDS:
            bn, bk, bm, bs = figures((g >= lo) & (g < hi))
            bands.append(f'{bm:.1f} % ({bs:+.1f}, {100 * bk / max(bn, 1):.0f} % covered)' if bk else '-')
        print(f'| {d} | {n} | {100 * k / max(n, 1):.1f} % | {med:.2f} % | {signed:+.2f} % | ' + ' | '.join(bands) + ' |')
    within = g <= 20.0
    print(f'\nFlat ground from the mount on the same road pixels (the road selection\'s check): '
          f'{100 * np.nanmedian(np.abs(p[within] - g[within]) / g[within]):.2f} %')


if __name__ == '__main__':
    main()
