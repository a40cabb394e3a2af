"""YOLO-format folders (images/NAME.png, labels/NAME.txt, classes.txt) read and checked.

A label line is `class cx cy w h`, centre and size normalised to the image. Every
problem is named with its file and line; the image it belongs to is skipped and
counted (Problems.summary()), so one bad label cannot teach the model that a
vehicle is background.
"""
import collections
import os

import cv2
import numpy as np

IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".bmp", ".pgm")
# A label may overhang the image by this much (normalised): rounding of exported boxes.
EDGE_TOLERANCE = 1e-3


class DatasetError(Exception):
    """A folder that cannot be used at all (training stops with this message)."""


class Problems:
    def __init__(self):
        self.items = []  # (kind, message)

    def add(self, kind, message):
        self.items.append((kind, message))

    def summary(self):
        return collections.Counter(k for k, _ in self.items)


def read_classes(folder):
    path = os.path.join(folder, "classes.txt")
    if not os.path.isfile(path):
        raise DatasetError(f"{path}: missing (one class name per line)")
    with open(path) as f:
        names = [line.strip() for line in f if line.strip()]
    if not names:
        raise DatasetError(f"{path}: no class names")
    if len(set(names)) != len(names):
        raise DatasetError(f"{path}: duplicate class names {names}")
    return names


def parse_label_file(path, num_classes, problems):
    """[(class, cx, cy, w, h)] or None when the file has a bad line or no boxes (reported)."""
    with open(path) as f:
        lines = f.read().splitlines()
    boxes = []
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        where = f"{path}:{n}"
        fields = line.split()
        try:
            if len(fields) != 5:
                raise ValueError(f"{len(fields)} fields, expected 5 (class cx cy w h)")
            cls = int(fields[0])
            cx, cy, w, h = (float(v) for v in fields[1:])
        except ValueError as e:
            problems.add("malformed line", f"{where}: '{line}': {e}")
            return None
        if not 0 <= cls < num_classes:
            problems.add("class id out of range",
                         f"{where}: class id {cls} is not in classes.txt (0..{num_classes - 1})")
            return None
        if not (w > 0 and h > 0):
            problems.add("empty box", f"{where}: width {w} height {h} must be positive")
            return None
        x0, y0, x1, y1 = cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2
        if min(x0, y0) < -EDGE_TOLERANCE or max(x1, y1) > 1 + EDGE_TOLERANCE:
            problems.add("box outside image",
                         f"{where}: box x {x0:.4f}..{x1:.4f} y {y0:.4f}..{y1:.4f} leaves the image (0..1)")
            return None
        boxes.append((cls, cx, cy, w, h))
    if not boxes:
        problems.add("empty label file", f"{path}: no boxes")
        return None
    return boxes


def list_items(folder, problems):
    """[(image_path, label_path)] of a folder; images without a label file are reported."""
    img_dir, lab_dir = os.path.join(folder, "images"), os.path.join(folder, "labels")
    for d in (img_dir, lab_dir):
        if not os.path.isdir(d):
            raise DatasetError(f"{d}: missing (a YOLO folder holds images/, labels/ and classes.txt)")
    items = []
    for name in sorted(os.listdir(img_dir)):
        stem, ext = os.path.splitext(name)
        if ext.lower() not in IMAGE_EXTS:
            continue
        label = os.path.join(lab_dir, stem + ".txt")
        if not os.path.isfile(label):
            problems.add("missing label file", f"{label}: missing for {os.path.join(img_dir, name)}")
            continue
        items.append((os.path.join(img_dir, name), label))
    return items


def image_size(path):
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    return None if img is None else (img.shape[1], img.shape[0])


class Sample:
    """One image with its boxes in image pixels (class, x_min, y_min, x_max, y_max)."""

    def __init__(self, path, grey, boxes):
        self.path, self.grey, self.boxes = path, grey, boxes


def load_folders(folders, problems, expected_size=None, max_items=None, keep_empty=False):
    """Reads folders with the same classes.txt. Images of another size than expected_size
    (default: the most common size among them) are skipped. max_items: evenly spaced subset.
    Returns (class names, [Sample], (width, height))."""
    classes, items = None, []
    for folder in folders:
        names = read_classes(folder)
        if classes is not None and names != classes:
            raise DatasetError(f"{folder}/classes.txt lists {names}, but {folders[0]}/classes.txt lists {classes}")
        classes = names
        items += list_items(folder, problems)
    if max_items and len(items) > max_items:
        items = [items[int(i * len(items) / max_items)] for i in range(max_items)]
    labelled = []
    for img, lab in items:
        boxes = parse_label_file(lab, len(classes), problems)
        if boxes is None and not (keep_empty and _is_empty(lab)):
            continue
        labelled.append((img, boxes or []))
    sizes = {}
    for img, _ in labelled:
        sizes[img] = image_size(img)
    if expected_size is None:
        counts = collections.Counter(s for s in sizes.values() if s)
        if not counts:
            raise DatasetError(f"no readable, correctly labelled images in {', '.join(folders)}")
        expected_size = counts.most_common(1)[0][0]
    samples = []
    for img, boxes in labelled:
        if sizes[img] is None:
            problems.add("unreadable image", f"{img}: cannot be read as an image")
            continue
        if sizes[img] != tuple(expected_size):
            problems.add("wrong image size", f"{img}: {sizes[img][0]}x{sizes[img][1]}, expected "
                         f"{expected_size[0]}x{expected_size[1]}")
            continue
        grey = cv2.imread(img, cv2.IMREAD_GRAYSCALE)
        w, h = expected_size
        px = np.array([[c, (cx - bw / 2) * w, (cy - bh / 2) * h, (cx + bw / 2) * w, (cy + bh / 2) * h]
                       for c, cx, cy, bw, bh in boxes], np.float32).reshape(-1, 5)
        px[:, [1, 3]] = px[:, [1, 3]].clip(0, w)
        px[:, [2, 4]] = px[:, [2, 4]].clip(0, h)
        samples.append(Sample(img, grey, px))
    return classes, samples, tuple(expected_size)


def _is_empty(label_path):
    with open(label_path) as f:
        return not f.read().strip()


def letterbox_geometry(iw, ih, nw, nh):
    """The C++ Letterbox::compute (keep aspect): scale_x, scale_y, pad_x, pad_y, resized w, h."""
    s = min(nw / iw, nh / ih)
    rw, rh = max(1, int(round(iw * s))), max(1, int(round(ih * s)))
    return rw / iw, rh / ih, float((nw - rw) // 2), float((nh - rh) // 2), rw, rh


def make_input(grey, nw, nh, mean, std, pad_value=114.0):
    """The C++ makeInputBlob for a grey image: replicated to 3 channels, letterboxed, (x - mean) / std.
    Returns a float32 [3, nh, nw] array and the letterbox geometry."""
    ih, iw = grey.shape[:2]
    sx, sy, px, py, rw, rh = letterbox_geometry(iw, ih, nw, nh)
    canvas = np.full((nh, nw), pad_value, np.float32)
    canvas[int(py):int(py) + rh, int(px):int(px) + rw] = cv2.resize(grey, (rw, rh), interpolation=cv2.INTER_LINEAR)
    chans = [(canvas - m) / s for m, s in zip(mean, std)]
    return np.stack(chans, 0).astype(np.float32), (sx, sy, px, py)
