/*
 * Plane-sweep stereo functions written once, for C++17 and OpenCL C 1.2.
 *
 * Included after camera_model_shared.h (C++ includes it itself; OpenCL
 * programs are built from camera_model_shared.h + this file + the kernels), so
 * the C++ reference sweep and the OpenCL kernels warp, score and select with
 * the same code. Everything here is single precision.
 *
 * Planes are given in the reference camera's frame as n . X = d (unit n,
 * d > 0 on the camera's side). The range (Euclidean distance along the unit
 * ray r) at which a pixel's ray meets the plane is t = d / (n . r).
 *
 * Cost = (1 - ZNCC) / 2 over a square window: 0 for a perfect match, 1 for a
 * perfect anti-correlation. FM_COST_INVALID marks a hypothesis that could not
 * be scored (window outside an image, masked, or untextured).
 */
#ifndef FISHEYE_MAPPING_CORE_PLANE_SWEEP_SHARED_H_
#define FISHEYE_MAPPING_CORE_PLANE_SWEEP_SHARED_H_

#ifndef FM_OPENCL
#include "fisheye_mapping/core/camera_model_shared.h"
namespace fisheye_mapping {
#endif

#ifdef FM_OPENCL
#define FM_FMIN(a, b) fmin(a, b)
#define FM_FMAX(a, b) fmax(a, b)
#else
#define FM_FMIN(a, b) std::fmin(a, b)
#define FM_FMAX(a, b) std::fmax(a, b)
#endif

#define FM_SWEEP_MAX_VIEWS 8
#define FM_COST_INVALID 2.0f
#define FM_FAMILY_FRONTO 0 /* parallel to the reference image plane; d = z-depth */
#define FM_FAMILY_GROUND 1 /* parallel to the ground */
#define FM_AGGREGATE_AVERAGE 0
#define FM_AGGREGATE_BEST_K 1
/* A window whose intensity standard deviation is below this (image values in
 * [0, 1]) carries no texture to correlate. */
#define FM_MIN_WINDOW_STD 0.004f

/* 32 bytes, no vector types, so the host struct has the kernel's layout. */
struct FmSweepPlane {
  float nx, ny, nz, d;
  int family; /* FM_FAMILY_* */
  int pad0, pad1, pad2;
};

/* T_view_ref: p_view = R * p_ref + t, R row-major. 48 bytes. */
struct FmViewPose {
  float r[9];
  float t[3];
};

#ifdef FM_OPENCL
typedef struct FmSweepPlane FmSweepPlane;
typedef struct FmViewPose FmViewPose;
#endif

/* Range along the unit ray (rx, ry, rz) to the plane; -1 when the ray does
 * not meet the plane in front of the camera. */
FM_FN float fm_plane_range(struct FmSweepPlane p, float rx, float ry, float rz) {
  float c = p.nx * rx + p.ny * ry + p.nz * rz;
  return c > 1e-6f ? p.d / (c > 1e-6f ? c : 1.0f) : -1.0f;
}

/* Bilinear sample of a row-major float image whose unusable (self-masked)
 * pixels hold a negative value; -1 outside the area covered by pixel centres
 * or where any of the four pixels is unusable. Branch-free (the loads are
 * clamped into the image), so vectorizers can run it across work items. */
FM_FN float fm_sample_bilinear(const FM_GLOBAL float* img, int width, int height, float u, float v) {
  int inside = u >= 0.0f && v >= 0.0f && u <= (float)(width - 1) && v <= (float)(height - 1);
  float uc = FM_FMIN(FM_FMAX(u, 0.0f), (float)(width - 1));
  float vc = FM_FMIN(FM_FMAX(v, 0.0f), (float)(height - 1));
  int x0 = (int)uc;
  int y0 = (int)vc;
  int x1 = x0 + 1 < width ? x0 + 1 : x0;
  int y1 = y0 + 1 < height ? y0 + 1 : y0;
  float ax = uc - (float)x0;
  float ay = vc - (float)y0;
  float p00 = img[y0 * width + x0], p01 = img[y0 * width + x1];
  float p10 = img[y1 * width + x0], p11 = img[y1 * width + x1];
  float top = p00 + ax * (p01 - p00);
  float bottom = p10 + ax * (p11 - p10);
  int usable = inside && p00 >= 0.0f && p01 >= 0.0f && p10 >= 0.0f && p11 >= 0.0f;
  return usable ? top + ay * (bottom - top) : -1.0f;
}

/* Intensity that view `cam` (pose T_view_ref) sees at the reference-frame
 * point (x, y, z); -1 when the point is outside its domain, image or mask. */
FM_FN float fm_warp_sample(const FM_CAM_SPACE FM_CAM_FLOAT* cam, const FM_CAM_SPACE struct FmViewPose* pose,
                           const FM_GLOBAL float* img, float x, float y, float z) {
  float vx = pose->r[0] * x + pose->r[1] * y + pose->r[2] * z + pose->t[0];
  float vy = pose->r[3] * x + pose->r[4] * y + pose->r[5] * z + pose->t[1];
  float vz = pose->r[6] * x + pose->r[7] * y + pose->r[8] * z + pose->t[2];
  float u, v;
  int ok = fm_project(cam, vx, vy, vz, &u, &v);
  return fm_sample_bilinear(img, cam->width, cam->height, ok ? u : -1.0f, ok ? v : -1.0f);
}

/* Cost from the window sums of the warped view W and reference R over n
 * pixels: sw = sum W, sww = sum W^2, swr = sum W R; mean_r, std_r of R over
 * the same window. */
FM_FN float fm_zncc_cost(float n, float sw, float sww, float swr, float mean_r, float std_r) {
  float mean_w = sw / n;
  float var_w = FM_FMAX(sww / n - mean_w * mean_w, 0.0f);
  float denom = FM_FMAX(FM_SQRT(var_w) * std_r, 1e-12f);
  float zncc = FM_FMIN(FM_FMAX((swr / n - mean_w * mean_r) / denom, -1.0f), 1.0f);
  int textured = std_r >= FM_MIN_WINDOW_STD && var_w >= FM_MIN_WINDOW_STD * FM_MIN_WINDOW_STD;
  return textured ? 0.5f * (1.0f - zncc) : FM_COST_INVALID;
}

/* Aggregates the per-view costs (FM_COST_INVALID = view unusable here): the
 * mean of the valid ones, or (best-k, occlusion-robust: a view that cannot
 * see the point does not spoil the others) the mean of the min(k, valid)
 * smallest. Invalid when no view is valid. Branch-free: ranks by pairwise
 * comparison (ties broken by view index). */
FM_FN float fm_aggregate(const float* costs, int views, int mode, int k) {
  int n = 0;
  float sum_all = 0.0f;
  for (int v = 0; v < views; ++v) {
    int valid = costs[v] < FM_COST_INVALID;
    n += valid;
    sum_all += valid ? costs[v] : 0.0f;
  }
  int take = (mode == FM_AGGREGATE_BEST_K && k < n) ? k : n;
  float sum_best = 0.0f;
  for (int v = 0; v < views; ++v) {
    int rank = 0;
    for (int w = 0; w < views; ++w) {
      rank += (costs[w] < costs[v] || (costs[w] == costs[v] && w < v)) ? 1 : 0;
    }
    sum_best += (costs[v] < FM_COST_INVALID && rank < take) ? costs[v] : 0.0f;
  }
  float sum = take == n ? sum_all : sum_best;
  return n > 0 ? sum / (float)(take > 0 ? take : 1) : FM_COST_INVALID;
}

/* Winner-takes-all over the cost volume of one pixel (cost of plane j at
 * volume[j * stride]), with the unit ray r of the pixel.
 * Returns 1 and writes
 *   *range      range along r of the best plane, refined (when `subpixel`)
 *               by the vertex of the parabola through the costs of the best
 *               plane and its two neighbours of the same family: inverse
 *               depth is interpolated for fronto-parallel planes, the
 *               plane's offset for ground planes;
 *   *best_cost  the lowest cost;
 *   *ratio      best / second-best cost in [0, 1] (0 = unique), where the
 *               second best is the lowest cost among the hypotheses whose
 *               range lies outside the interval spanned by the best plane's
 *               two neighbours (so a neighbour of the minimum, or a plane
 *               of the other family through the same point, does not count);
 * returns 0 when no plane has a valid cost. */
FM_FN int fm_select_plane(const FM_GLOBAL float* volume, int stride, const FM_GLOBAL struct FmSweepPlane* planes,
                          int n_planes, float rx, float ry, float rz, int subpixel, float* range,
                          float* best_cost, float* ratio) {
  int best = -1;
  float cb = FM_COST_INVALID;
  for (int j = 0; j < n_planes; ++j) {
    float c = volume[j * stride];
    if (c < cb) {
      cb = c;
      best = j;
    }
  }
  if (best < 0) {
    return 0;
  }
  struct FmSweepPlane pb = planes[best];
  int prev = (best > 0 && planes[best - 1].family == pb.family) ? best - 1 : -1;
  int next = (best + 1 < n_planes && planes[best + 1].family == pb.family) ? best + 1 : -1;
  float tb = fm_plane_range(pb, rx, ry, rz);
  float lo = tb, hi = tb;
  float d = pb.d;
  if (prev >= 0) {
    float t = fm_plane_range(planes[prev], rx, ry, rz);
    if (t > 0.0f) {
      lo = t < lo ? t : lo;
      hi = t > hi ? t : hi;
    }
  }
  if (next >= 0) {
    float t = fm_plane_range(planes[next], rx, ry, rz);
    if (t > 0.0f) {
      lo = t < lo ? t : lo;
      hi = t > hi ? t : hi;
    }
  }
  if (subpixel && prev >= 0 && next >= 0) {
    float c0 = volume[prev * stride];
    float c2 = volume[next * stride];
    float denom = c0 - 2.0f * cb + c2;
    if (c0 < FM_COST_INVALID && c2 < FM_COST_INVALID && denom > 1e-9f) {
      float off = 0.5f * (c0 - c2) / denom;
      off = off > 0.5f ? 0.5f : (off < -0.5f ? -0.5f : off);
      float d_other = off >= 0.0f ? planes[next].d : planes[prev].d;
      float a = off >= 0.0f ? off : -off;
      if (pb.family == FM_FAMILY_FRONTO) {
        d = 1.0f / (1.0f / pb.d + a * (1.0f / d_other - 1.0f / pb.d));
      } else {
        d = pb.d + a * (d_other - pb.d);
      }
    }
  }
  pb.d = d;
  float second = FM_COST_INVALID;
  for (int j = 0; j < n_planes; ++j) {
    if (j == best || j == prev || j == next) {
      continue;
    }
    float c = volume[j * stride];
    if (!(c < second)) {
      continue;
    }
    float t = fm_plane_range(planes[j], rx, ry, rz);
    if (t >= lo && t <= hi) {
      continue;
    }
    second = c;
  }
  *range = fm_plane_range(pb, rx, ry, rz);
  *best_cost = cb;
  *ratio = second < FM_COST_INVALID ? (second > 0.0f ? cb / second : 1.0f) : 0.0f;
  return *range > 0.0f;
}

#ifndef FM_OPENCL
}  // namespace fisheye_mapping
#endif

#endif /* FISHEYE_MAPPING_CORE_PLANE_SWEEP_SHARED_H_ */
