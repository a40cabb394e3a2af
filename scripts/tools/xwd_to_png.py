#!/usr/bin/env python3
"""Converts an X window dump (xwd, ZPixmap, 24/32 bits per pixel) to PNG.

usage: xwd_to_png.py IN.xwd OUT.png [--crop x,y,w,h]
"""
import struct
import sys

import cv2
import numpy as np


def main():
    src, dst = sys.argv[1], sys.argv[2]
    data = open(src, "rb").read()
    h = struct.unpack(">25I", data[:100])
    header_size, fmt, depth, width, height = h[0], h[2], h[3], h[4], h[5]
    byte_order, bpp, bpl, ncolors = h[7], h[11], h[12], h[19]
    if fmt != 2 or bpp not in (24, 32):
        sys.exit(f"{src}: only ZPixmap with 24/32 bits per pixel is supported (format {fmt}, {bpp} bpp)")
    off = header_size + 12 * ncolors
    rows = np.frombuffer(data, np.uint8, count=bpl * height, offset=off).reshape(height, bpl)
    px = rows[:, : width * bpp // 8].reshape(height, width, bpp // 8)
    if byte_order == 1:  # MSB first: XRGB
        px = px[:, :, ::-1]
    img = np.ascontiguousarray(px[:, :, :3])  # BGR
    if len(sys.argv) > 4 and sys.argv[3] == "--crop":
        x, y, w, hh = (int(v) for v in sys.argv[4].split(","))
        img = img[y:y + hh, x:x + w]
    if not cv2.imwrite(dst, img):
        sys.exit(f"cannot write {dst}")


if __name__ == "__main__":
    main()
