#!/usr/bin/env python3
"""Integrates the frames written by tsdf_benchmark with Open3D 0.16 (CPU):
VoxelBlockGrid and ScalableTSDFVolume, 5 cm voxels, 0.2 m truncation.
Prints ms per frame for each and the process's peak RSS."""
import resource
import sys
import time
from pathlib import Path

import numpy as np
import open3d as o3d
import open3d.core as o3c

out = Path(sys.argv[1])
w, h, fx, fy, cx, cy = open(out / "intrinsics.txt").read().split()
w, h = int(w), int(h)
fx, fy, cx, cy = map(float, (fx, fy, cx, cy))
poses = np.loadtxt(out / "poses.txt").reshape(-1, 4, 4)
frames = [np.fromfile(out / f"frame_{i:03d}.bin", dtype=np.float32).reshape(h, w) for i in range(len(poses))]
valid = np.mean([np.count_nonzero(f > 0) for f in frames])
K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]])
voxel, trunc, depth_max = 0.05, 0.2, 1000.0

device = o3c.Device("CPU:0")
vbg = o3d.t.geometry.VoxelBlockGrid(attr_names=("tsdf", "weight"), attr_dtypes=(o3c.float32, o3c.float32),
                                    attr_channels=((1), (1)), voxel_size=voxel, block_resolution=8,
                                    block_count=200000, device=device)
intrinsic = o3c.Tensor(K, o3c.float64)
times = []
for depth_np, T_W_C in zip(frames, poses):
    depth = o3d.t.geometry.Image(o3c.Tensor(depth_np)).to(device)
    extrinsic = o3c.Tensor(np.linalg.inv(T_W_C), o3c.float64)
    start = time.perf_counter()
    blocks = vbg.compute_unique_block_coordinates(depth, intrinsic, extrinsic, 1.0, depth_max,
                                                  trunc_voxel_multiplier=trunc / voxel)
    vbg.integrate(blocks, depth, intrinsic, extrinsic, 1.0, depth_max, trunc_voxel_multiplier=trunc / voxel)
    times.append((time.perf_counter() - start) * 1e3)
print(f"open3d VoxelBlockGrid: {np.mean(times):.1f} ms/frame (median {np.median(times):.1f}), "
      f"{valid:.0f} valid pixels/frame")

volume = o3d.pipelines.integration.ScalableTSDFVolume(
    voxel_length=voxel, sdf_trunc=trunc, color_type=o3d.pipelines.integration.TSDFVolumeColorType.NoColor)
camera = o3d.camera.PinholeCameraIntrinsic(w, h, fx, fy, cx, cy)
gray = o3d.geometry.Image(np.zeros((h, w), dtype=np.float32))
times = []
for depth_np, T_W_C in zip(frames, poses):
    rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
        gray, o3d.geometry.Image(depth_np), depth_scale=1.0, depth_trunc=depth_max, convert_rgb_to_intensity=False)
    start = time.perf_counter()
    volume.integrate(rgbd, camera, np.linalg.inv(T_W_C))
    times.append((time.perf_counter() - start) * 1e3)
print(f"open3d ScalableTSDFVolume: {np.mean(times):.1f} ms/frame (median {np.median(times):.1f})")
print(f"open3d peak RSS: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
