#!/usr/bin/env python3
"""Where two maps' trail points differ: the points of each map cloud farther
than --tol (0.25 m, map_accuracy's --trail-tol) from a drive's static scene
mesh, and those of one map with no trail point of the other within --near
(0.5 m), grouped in 3 m cells of the ground plane (largest first).

usage: trail_points.py SCENE.ply MAP_A.pcd [MAP_B.pcd] [--tol M] [--near M]

Tells whether a detector's map has trail voxels where the oracle's has none
(a vehicle masked too little) or more of them in the same places (the same
depth outliers fused a little differently). SCENE.ply: make_drive's
static_scene.ply (binary little-endian triangles); MAP_*.pcd: offline_mapper's
cloud.pcd (binary PCD with x, y, z). The mesh is sampled every 4 cm, so a
distance is the mesh's within 3 cm.
"""
import argparse
import sys

import numpy as np
from scipy.spatial import cKDTree


def read_ply(path):
    """Vertices (N x 3) and triangles (M x 3) of a binary little-endian PLY."""
    with open(path, 'rb') as f:
        nv = nf = 0
        if f.readline().strip() != b'ply':
            sys.exit(f'trail_points: {path} is not a PLY file')
        while True:
            line = f.readline()
            if not line:
                sys.exit(f'trail_points: {path}: no end_header')
            words = line.decode('ascii', 'replace').split()
            if words[:1] == ['format'] and words[1] != 'binary_little_endian':
                sys.exit(f'trail_points: {path}: format {words[1]}, binary_little_endian needed')
            if words[:2] == ['element', 'vertex']:
                nv = int(words[2])
            if words[:2] == ['element', 'face']:
                nf = int(words[2])
            if words == ['end_header']:
                break
        v = np.frombuffer(f.read(nv * 12), dtype='<f4')
        faces = np.frombuffer(f.read(nf * 13), dtype=np.dtype([('n', 'u1'), ('i', '<i4', (3,))]))
    if v.size != 3 * nv or len(faces) != nf or not (faces['n'] == 3).all():
        sys.exit(f'trail_points: {path}: truncated, or not 3 float vertices and triangles')
    return v.reshape(nv, 3).astype(np.float64), faces['i']


def read_pcd(path):
    """x, y, z (N x 3) of a binary PCD."""
    with open(path, 'rb') as f:
        head = {}
        while True:
            line = f.readline()
            if not line:
                sys.exit(f'trail_points: {path}: no DATA line')
            words = line.decode('ascii', 'replace').split()
            if words and not words[0].startswith('#'):
                head[words[0]] = words[1:]
            if words[:1] == ['DATA']:
                break
        if head['DATA'][0] != 'binary':
            sys.exit(f'trail_points: {path}: DATA {head["DATA"][0]}, binary needed')
        kinds = {'F': 'f', 'U': 'u', 'I': 'i'}
        dt = np.dtype([(name, '<' + kinds[t] + s) for name, s, t in zip(head['FIELDS'], head['SIZE'], head['TYPE'])])
        n = int(head['POINTS'][0])
        a = np.frombuffer(f.read(n * dt.itemsize), dtype=dt)
    if len(a) != n:
        sys.exit(f'trail_points: {path}: {len(a)} of {n} points')
    return np.stack([a['x'], a['y'], a['z']], 1).astype(np.float64)


def sample_mesh(v, tris, step=0.04):
    """Points on every triangle, no two neighbours farther apart than step."""
    out = []
    for tri in tris:
        a, b, c = v[tri]
        edge = max(np.linalg.norm(b - a), np.linalg.norm(c - a), np.linalg.norm(c - b))
        n = max(1, int(np.ceil(edge / step)))
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
        keep = i + j <= n
        out.append(a + np.outer(i[keep] / n, b - a) + np.outer(j[keep] / n, c - a))
    return np.concatenate(out) if out else np.zeros((0, 3))


def trail_points(scene_tree, cloud, tol):
    d, _ = scene_tree.query(cloud, distance_upper_bound=tol + 0.05)
    return cloud[d > tol]


def only_in(a, b, near):
    """Points of a with no point of b within near."""
    if len(a) == 0 or len(b) == 0:
        return a
    d, _ = cKDTree(b).query(a, distance_upper_bound=near)
    return a[d > near]


def cells(points, size=3.0, top=10):
    """(cell centre x, y, count, z min, z max) of the most populated cells."""
    if len(points) == 0:
        return []
    key = np.floor(points[:, :2] / size).astype(int)
    uniq, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    out = []
    for k in np.argsort(-cnt)[:top]:
        z = points[inv == k, 2]
        out.append(((uniq[k][0] + 0.5) * size, (uniq[k][1] + 0.5) * size, int(cnt[k]), z.min(), z.max()))
    return out


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('scene')
    ap.add_argument('maps', nargs='+')
    ap.add_argument('--tol', type=float, default=0.25)
    ap.add_argument('--near', type=float, default=0.5)
    args = ap.parse_args(argv)
    if len(args.maps) > 2:
        ap.error('one or two maps')
    tree = cKDTree(sample_mesh(*read_ply(args.scene)))
    trails = []
    for m in args.maps:
        cloud = read_pcd(m)
        trails.append(trail_points(tree, cloud, args.tol))
        print(f'{m}: {len(cloud)} points, {len(trails[-1])} trail points (farther than {args.tol} m from the scene)')
    if len(trails) == 2:
        for (name, a), b in zip(((args.maps[0], trails[0]), (args.maps[1], trails[1])), (trails[1], trails[0])):
            o = only_in(a, b, args.near)
            print(f'only in {name} (no trail point of the other within {args.near} m): {len(o)}')
            for x, y, n, z0, z1 in cells(o):
                print(f'  cell ({x:.1f}, {y:.1f}): {n} points, z {z0:.2f}..{z1:.2f} m')


if __name__ == '__main__':
    main(sys.argv[1:])
