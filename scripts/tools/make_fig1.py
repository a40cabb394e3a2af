#!/usr/bin/env python3
"""The paper's Fig. 1 from a demo run: (a) the reference camera's image,
(b) its depth (colour-mapped), (c) the detections (boxes drawn on the image),
(d) the 3D map (vehicles removed by the pipeline's masking) rendered offscreen
from the exported mesh, with the PLY's per-vertex colours (red/green/blue,
e.g. the fused grey intensity) or a plain grey where it has none, Lambert
shaded from the vertex normals.

usage: make_fig1.py --frame-dir DIR --mesh MESH.ply --out fig1.png
                    [--panel-width 900] [--title TEXT]
       make_fig1.py --mesh MESH.ply --render-only OUT.png [--width W --height H]

DIR holds frame_image.png, frame_depth.png and frame_detections.png (written
mid-drive by scripts/tools/grab_frame.py from the running pipeline's topics)
and frame.txt. The renderer is numpy + OpenCV only (a z-buffer over points
sampled on every triangle; no OpenGL, so it works headless anywhere); the
view looks along the principal horizontal axis of the mesh's vertices (the street)
from behind, above and a little to the side.
"""
import argparse
import os
import sys

import cv2
import numpy as np

PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
             "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
             "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def read_ply(path):
    """Binary little-endian or ASCII PLY -> dict: vertices (N,3), normals (N,3) or None,
    colours (N,3) uint8 RGB or None, faces (M,3) int (triangles; polygons fanned)."""
    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            raise ValueError(f"{path}: not a PLY file")
        fmt = None
        elements = []   # [name, count, [(prop name, type) or (name, (count type, item type))]]
        while True:
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: no end_header")
            tok = line.decode("ascii", "replace").split()
            if not tok or tok[0] in ("comment", "obj_info"):
                continue
            if tok[0] == "format":
                fmt = tok[1]
            elif tok[0] == "element":
                elements.append([tok[1], int(tok[2]), []])
            elif tok[0] == "property":
                if tok[1] == "list":
                    elements[-1][2].append((tok[4], (PLY_TYPES[tok[2]], PLY_TYPES[tok[3]])))
                else:
                    elements[-1][2].append((tok[2], PLY_TYPES[tok[1]]))
            elif tok[0] == "end_header":
                break
        data = {}
        if fmt == "ascii":
            rest = f.read().decode("ascii").split()
            pos = 0
            for name, count, props in elements:
                if all(not isinstance(t, tuple) for _, t in props):
                    n = len(props)
                    arr = np.array(rest[pos:pos + n * count], dtype=np.float64).reshape(count, n)
                    pos += n * count
                    data[name] = {p: arr[:, i] for i, (p, _) in enumerate(props)}
                else:
                    rows = []
                    for _ in range(count):
                        k = int(rest[pos])
                        rows.append([int(v) for v in rest[pos + 1:pos + 1 + k]])
                        pos += 1 + k
                    data[name] = {"_lists": rows}
        elif fmt == "binary_little_endian":
            buf = f.read()
            pos = 0
            for name, count, props in elements:
                if all(not isinstance(t, tuple) for _, t in props):
                    dt = np.dtype([(p, "<" + t) for p, t in props])
                    arr = np.frombuffer(buf, dt, count=count, offset=pos)
                    pos += dt.itemsize * count
                    data[name] = {p: arr[p] for p, _ in props}
                elif len(props) == 1:
                    ct, it = props[0][1]
                    # Fast path: every list has 3 items (the TSDF mesher writes triangles).
                    dt = np.dtype([("n", "<" + ct), ("i", "<" + it, (3,))])
                    arr = np.frombuffer(buf, dt, count=count, offset=pos) if pos + dt.itemsize * count <= len(buf) else None
                    if arr is not None and count and np.all(arr["n"] == 3):
                        pos += dt.itemsize * count
                        data[name] = {"_tri": arr["i"].astype(np.int64)}
                    else:
                        rows = []
                        cs, isz = np.dtype(ct).itemsize, np.dtype(it).itemsize
                        for _ in range(count):
                            k = int(np.frombuffer(buf, "<" + ct, 1, pos)[0])
                            rows.append(np.frombuffer(buf, "<" + it, k, pos + cs).tolist())
                            pos += cs + k * isz
                        data[name] = {"_lists": rows}
                else:
                    raise ValueError(f"{path}: element {name} mixes lists and scalars (not supported)")
        else:
            raise ValueError(f"{path}: PLY format {fmt} not supported")
    v = data.get("vertex")
    if v is None:
        raise ValueError(f"{path}: no vertices")
    verts = np.stack([v["x"], v["y"], v["z"]], 1).astype(np.float64)
    normals = np.stack([v["nx"], v["ny"], v["nz"]], 1).astype(np.float64) if "nx" in v else None
    colours = None
    for r, g, b in (("red", "green", "blue"), ("r", "g", "b"), ("diffuse_red", "diffuse_green", "diffuse_blue")):
        if r in v:
            colours = np.stack([v[r], v[g], v[b]], 1)
            if colours.dtype.kind == "f" and colours.max() <= 1.0:
                colours = colours * 255
            colours = np.clip(colours, 0, 255).astype(np.uint8)
            break
    faces = np.zeros((0, 3), np.int64)
    fe = data.get("face")
    if fe is not None:
        if "_tri" in fe:
            faces = fe["_tri"]
        else:
            tris = [(p[0], p[i], p[i + 1]) for p in fe["_lists"] for i in range(1, len(p) - 1)]
            faces = np.array(tris, np.int64).reshape(-1, 3)
    return {"vertices": verts, "normals": normals, "colours": colours, "faces": faces}


def vertex_normals(verts, faces):
    n = np.zeros_like(verts)
    fn = np.cross(verts[faces[:, 1]] - verts[faces[:, 0]], verts[faces[:, 2]] - verts[faces[:, 0]])
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def default_view(verts, trajectory=None):
    """Eye behind and above the map's middle, looking along its main horizontal axis."""
    xy = verts[:, :2]
    lo, hi = np.percentile(xy, 2, axis=0), np.percentile(xy, 98, axis=0)
    centre_xy = (lo + hi) / 2
    ground = np.percentile(verts[:, 2], 10)
    d = xy - centre_xy
    if trajectory is not None and len(trajectory) > 1:
        axis = trajectory[-1, :2] - trajectory[0, :2]
    else:
        w, vecs = np.linalg.eigh(np.cov(d[:: max(1, len(d) // 200000)].T))
        axis = vecs[:, np.argmax(w)]
        # drive direction unknown: look towards the side with more vertices far out (arbitrary but stable)
    axis = axis / max(np.linalg.norm(axis), 1e-9)
    proj = d @ axis
    length = np.percentile(proj, 98) - np.percentile(proj, 2)
    target = np.array([centre_xy[0], centre_xy[1], ground])
    # a little to one side, so that the facades of that side are seen at an angle, not edge-on
    side = np.array([-axis[1], axis[0], 0.0])
    eye = target - np.r_[axis, 0] * (0.45 * length) + side * (0.30 * length) + np.array([0, 0, 0.22 * length])
    return eye, target


def render(mesh, width=1600, height=900, eye=None, target=None, fov_deg=50.0, light=None, background=(255, 255, 255)):
    """Offscreen render of a triangle mesh: z-buffer over points sampled on each
    triangle (spacing under a pixel), colours interpolated from the vertices,
    Lambert (two-sided, with ambient) from the interpolated vertex normals.
    Returns BGR uint8."""
    verts, faces = mesh["vertices"], mesh["faces"]
    normals = mesh["normals"]
    if normals is None or not np.isfinite(normals).all() or np.allclose(normals, 0):
        normals = vertex_normals(verts, faces)
    else:
        normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    colours = mesh["colours"]
    if colours is None:
        colours = np.full((len(verts), 3), 200, np.uint8)
    if eye is None or target is None:
        eye, target = default_view(verts)
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    fwd = target - eye
    fwd /= np.linalg.norm(fwd)
    up = np.array([0.0, 0.0, 1.0])
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    cam_up = np.cross(right, fwd)
    R = np.stack([right, -cam_up, fwd])   # world -> camera (x right, y down, z forward)
    focal = 0.5 * width / np.tan(np.radians(fov_deg) / 2)
    if light is None:   # from above, over the viewer's shoulder
        light = -fwd * 0.5 + np.array([0.0, 0.0, 1.0]) + right * 0.3
    light = np.asarray(light, float) / np.linalg.norm(light)
    shade = 0.30 + 0.70 * np.abs(normals @ light)
    vcol = colours.astype(np.float32) * shade[:, None].astype(np.float32)

    pc = (verts - eye) @ R.T
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = focal * pc[:, 0] / z + width / 2
        v = focal * pc[:, 1] / z + height / 2
    near = 0.5
    fz = z[faces]
    keep = np.all(fz > near, axis=1)
    fu, fv = u[faces], v[faces]
    keep &= ~((fu.max(1) < 0) | (fu.min(1) >= width) | (fv.max(1) < 0) | (fv.min(1) >= height))
    faces = faces[keep]
    fu, fv, fz = fu[keep], fv[keep], fz[keep]
    edge = np.maximum.reduce([np.hypot(fu[:, 0] - fu[:, 1], fv[:, 0] - fv[:, 1]),
                              np.hypot(fu[:, 1] - fu[:, 2], fv[:, 1] - fv[:, 2]),
                              np.hypot(fu[:, 2] - fu[:, 0], fv[:, 2] - fv[:, 0])])
    nsub = np.clip(np.ceil(edge / 0.7).astype(np.int64), 1, 400)
    zbuf = np.full(width * height, np.inf, np.float32)
    cbuf = np.zeros((width * height, 3), np.float32)
    for n in np.unique(nsub):
        sel = np.nonzero(nsub == n)[0]
        # barycentric grid with n+1 points per edge
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        m = (i + j) <= n
        w1, w2 = (i[m] / n).astype(np.float32), (j[m] / n).astype(np.float32)
        w0 = 1 - w1 - w2
        # chunks keep memory bounded
        chunk = max(1, 4_000_000 // len(w0))
        for s in range(0, len(sel), chunk):
            f = sel[s:s + chunk]
            fa = faces[f]
            # perspective-correct enough at this scale: interpolate in 3D camera space, project each sample
            P = (w0[None, :, None] * pc[fa[:, 0]][:, None, :] + w1[None, :, None] * pc[fa[:, 1]][:, None, :]
                 + w2[None, :, None] * pc[fa[:, 2]][:, None, :]).reshape(-1, 3)
            C = (w0[None, :, None] * vcol[fa[:, 0]][:, None, :] + w1[None, :, None] * vcol[fa[:, 1]][:, None, :]
                 + w2[None, :, None] * vcol[fa[:, 2]][:, None, :]).reshape(-1, 3)
            zz = P[:, 2]
            uu = np.floor(focal * P[:, 0] / zz + width / 2).astype(np.int64)
            vv = np.floor(focal * P[:, 1] / zz + height / 2).astype(np.int64)
            ok = (zz > near) & (uu >= 0) & (uu < width) & (vv >= 0) & (vv < height)
            idx = vv[ok] * width + uu[ok]
            zz, C = zz[ok].astype(np.float32), C[ok]
            # nearest sample per pixel within the chunk, then against the buffer
            o = np.lexsort((zz, idx))
            idx, zz, C = idx[o], zz[o], C[o]
            first = np.r_[True, idx[1:] != idx[:-1]]
            idx, zz, C = idx[first], zz[first], C[first]
            better = zz < zbuf[idx]
            zbuf[idx[better]] = zz[better]
            cbuf[idx[better]] = C[better]
    img = np.empty((height, width, 3), np.uint8)
    img[:] = background[::-1]
    hit = np.isfinite(zbuf).reshape(height, width)
    rgb = np.clip(cbuf, 0, 255).astype(np.uint8).reshape(height, width, 3)
    img[hit] = rgb[hit][:, ::-1]   # RGB -> BGR
    return img


def label(img, text, scale=1.0):
    out = img.copy()
    th = max(1, int(round(2 * scale)))
    (tw, tht), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.9 * scale, th)
    cv2.rectangle(out, (0, 0), (tw + 16, tht + base + 14), (255, 255, 255), -1)
    cv2.putText(out, text, (8, tht + 8), cv2.FONT_HERSHEY_SIMPLEX, 0.9 * scale, (0, 0, 0), th, cv2.LINE_AA)
    return out


def fit(img, width):
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    h = int(round(img.shape[0] * width / img.shape[1]))
    return cv2.resize(img, (width, h), interpolation=cv2.INTER_AREA)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frame-dir")
    ap.add_argument("--mesh", required=True)
    ap.add_argument("--out")
    ap.add_argument("--render-only", metavar="OUT.png")
    ap.add_argument("--panel-width", type=int, default=900)
    ap.add_argument("--width", type=int, default=1600)
    ap.add_argument("--height", type=int, default=900)
    ap.add_argument("--title", default="")
    args = ap.parse_args()
    mesh = read_ply(args.mesh)
    if len(mesh["faces"]) == 0:
        sys.exit(f"{args.mesh}: no triangles")
    print(f"{args.mesh}: {len(mesh['vertices'])} vertices, {len(mesh['faces'])} triangles, "
          f"{'vertex colours' if mesh['colours'] is not None else 'no vertex colours (grey)'}, "
          f"{'normals' if mesh['normals'] is not None else 'normals from the faces'}")
    if args.render_only:
        cv2.imwrite(args.render_only, render(mesh, args.width, args.height))
        return
    if not (args.frame_dir and args.out):
        sys.exit("make_fig1.py: --frame-dir and --out are needed (or --render-only)")
    pw = args.panel_width
    imgs = []
    for name in ("frame_image.png", "frame_depth.png", "frame_detections.png"):
        p = os.path.join(args.frame_dir, name)
        im = cv2.imread(p, cv2.IMREAD_COLOR)
        if im is None:
            sys.exit(f"make_fig1.py: cannot read {p}")
        imgs.append(fit(im, pw))
    ph = imgs[0].shape[0]
    mapimg = render(mesh, 2 * pw, int(round(2 * pw * 9 / 16)))
    mapimg = cv2.resize(mapimg, (pw, int(round(pw * 9 / 16))), interpolation=cv2.INTER_AREA)  # 2x supersampled
    # (d) gets the same height as the image panels: pad or crop the middle
    if mapimg.shape[0] > ph:
        o = (mapimg.shape[0] - ph) // 2
        mapimg = mapimg[o:o + ph]
    elif mapimg.shape[0] < ph:
        pad = ph - mapimg.shape[0]
        mapimg = cv2.copyMakeBorder(mapimg, pad // 2, pad - pad // 2, 0, 0, cv2.BORDER_CONSTANT, value=(255, 255, 255))
    s = pw / 900
    info = {}
    fp = os.path.join(args.frame_dir, "frame.txt")
    if os.path.exists(fp):
        for line in open(fp):
            k, _, v = line.partition(":")
            info[k.strip()] = v.strip()
    oracle = info.get("detections", "").startswith("boxes of")
    a = label(imgs[0], "(a) reference camera image", s)
    b = label(imgs[1], f"(b) depth (plane sweep; red near, blue {float(info.get('max_range', 15)):.0f} m)", s)
    c = label(imgs[2], "(c) detections" + (" (oracle: true boxes)" if oracle else ""), s)
    d = label(mapimg, "(d) 3D map, vehicles removed (mesh)", s)
    gap = 8
    white_v = np.full((ph, gap, 3), 255, np.uint8)
    row1 = np.hstack([a, white_v, b])
    row2 = np.hstack([c, white_v, d])
    fig = np.vstack([row1, np.full((gap, row1.shape[1], 3), 255, np.uint8), row2])
    if args.title:
        bar = np.full((int(50 * s), fig.shape[1], 3), 255, np.uint8)
        cv2.putText(bar, args.title, (10, int(34 * s)), cv2.FONT_HERSHEY_SIMPLEX, 0.9 * s, (0, 0, 0), max(1, int(2 * s)), cv2.LINE_AA)
        fig = np.vstack([bar, fig])
    if not cv2.imwrite(args.out, fig):
        sys.exit(f"cannot write {args.out}")
    print(f"fig1: {args.out} ({fig.shape[1]}x{fig.shape[0]})")


if __name__ == "__main__":
    main()
