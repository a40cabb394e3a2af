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
#ifndef FISHEYE_MAPPING_CORE_DEPTH_PLANE_SWEEP_SHARED_H_
#define FISHEYE_MAPPING_CORE_DEPTH_PLANE_SWEEP_SHARED_H_

#ifndef FM_OPENCL
#include "fisheye_mapping/core/camera/camera_model_shared.h"
namespace fisheye_mapping {
#endif

/* max / clamp as selects. A NaN x gives lo, exactly as fmax(x, lo) and
 * fmin(fmax(x, lo), hi) do, but unlike std::fmin/fmax (libm calls unless
 * -ffinite-math-only) they vectorize in C++ as well as in OpenCL C. */
FM_FN float fm_maxf(float x, float lo) { return x > lo ? x : lo; }
FM_FN float fm_clampf(float x, float lo, float hi) { return x >= lo ? (x <= hi ? x : hi) : lo; }

#define FM_SWEEP_MAX_VIEWS 8
/* Side of the square tiles of a level's plane activity (SweepLevel::active):
 * a plane is swept, or not, for whole tiles of FM_SWEEP_TILE^2 pixels. */
#define FM_SWEEP_TILE 8
#define FM_COST_INVALID 2.0f
#define FM_FAMILY_FRONTO 0 /* parallel to the reference image plane; d = z-depth */
#define FM_FAMILY_GROUND 1 /* parallel to the ground */
#define FM_FAMILY_WALL_LEFT 2  /* vertical, parallel to the driving direction, left of the base */
#define FM_FAMILY_WALL_RIGHT 3 /* the same, right of the base */
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

/* Bilinear sampling of a row-major float image whose unusable (self-masked)
 * pixels hold a negative value, in two halves so that a backend may do the
 * four loads its own way between them (the native CPU backend loads them
 * scalar: faster than gathers on CPUs):
 *   fm_bilinear_setup: where the sample reads (index of the top-left pixel,
 *     steps to its right and lower neighbours: 0 at the last column / row)
 *     and its weights; returns whether (u, v) lies inside the area covered
 *     by pixel centres (NaN: outside; outside reads pixel 0);
 *   fm_bilinear_blend: the sample from the four pixels; -1 when outside or
 *     when any of the four is unusable.
 * No control flow: & of 0/1 ints rather than &&, selects rather than clamps,
 * and the result blended arithmetically (a select on loaded values defeats
 * GCC's if-conversion; ok * r + (ok - 1) is exactly r or -1 for the finite r
 * here), so C++ compilers vectorize it as OpenCL does. */
FM_FN int fm_bilinear_setup(int width, int height, float u, float v, int* i00, int* dx, int* dy, float* ax,
                            float* ay) {
  int inside = (u >= 0.0f ? 1 : 0) & (v >= 0.0f ? 1 : 0) & (u <= (float)(width - 1) ? 1 : 0) &
               (v <= (float)(height - 1) ? 1 : 0);
  float uc = inside ? u : 0.0f;
  float vc = inside ? v : 0.0f;
  int x0 = (int)uc;
  int y0 = (int)vc;
  *i00 = y0 * width + x0;
  *dx = x0 + 1 < width ? 1 : 0;
  *dy = y0 + 1 < height ? width : 0;
  *ax = uc - (float)x0;
  *ay = vc - (float)y0;
  return inside;
}

FM_FN float fm_bilinear_blend(int inside, float p00, float p01, float p10, float p11, float ax, float ay) {
  float top = p00 + ax * (p01 - p00);
  float bottom = p10 + ax * (p11 - p10);
  float ok = (float)(inside & (p00 >= 0.0f ? 1 : 0) & (p01 >= 0.0f ? 1 : 0) & (p10 >= 0.0f ? 1 : 0) &
                     (p11 >= 0.0f ? 1 : 0));
  return ok * (top + ay * (bottom - top)) + (ok - 1.0f);
}

/* The two halves with the loads between: -1 outside the area covered by pixel
 * centres or where any of the four pixels is unusable. */
FM_FN float fm_sample_bilinear(const FM_GLOBAL float* img, int width, int height, float u, float v) {
  int i00, dx, dy;
  float ax, ay;
  int inside = fm_bilinear_setup(width, height, u, v, &i00, &dx, &dy, &ax, &ay);
  return fm_bilinear_blend(inside, img[i00], img[i00 + dx], img[i00 + dy], img[i00 + dy + dx], ax, ay);
}

/* Inverse range s = (n . r) / d along the unit ray r to the plane: positive
 * when the ray meets the plane in front of the camera (n . r > 1e-6, as in
 * fm_plane_range), else 0. */
FM_FN float fm_plane_inverse_range(struct FmSweepPlane p, float rx, float ry, float rz) {
  float c = p.nx * rx + p.ny * ry + p.nz * rz;
  return c > 1e-6f ? c * (1.0f / p.d) : 0.0f;
}

/* Where view `cam` (pose T_view_ref: R, t) sees the point at inverse range s
 * (> 0) along the reference ray r, i.e. r / s. Central projections do not
 * change when the point is scaled by s > 0, so the point projected is
 * R r + s t: no division. Returns whether it is in the view's model domain. */
FM_FN int fm_warp_project_ray(const FM_CAM_SPACE FM_CAM_FLOAT* cam, const FM_CAM_SPACE struct FmViewPose* pose,
                              float rx, float ry, float rz, float s, float* u, float* v) {
  float vx = pose->r[0] * rx + pose->r[1] * ry + pose->r[2] * rz + s * pose->t[0];
  float vy = pose->r[3] * rx + pose->r[4] * ry + pose->r[5] * rz + s * pose->t[1];
  float vz = pose->r[6] * rx + pose->r[7] * ry + pose->r[8] * rz + s * pose->t[2];
  return fm_project(cam, vx, vy, vz, u, v) & (s > 0.0f ? 1 : 0);
}

/* Intensity that view `cam` sees where the reference ray r meets the plane at
 * inverse range s (fm_plane_inverse_range); -1 when the ray misses the plane
 * (s = 0) or the point is outside the view's domain, image or mask. */
FM_FN float fm_warp_sample_ray(const FM_CAM_SPACE FM_CAM_FLOAT* cam, const FM_CAM_SPACE struct FmViewPose* pose,
                               const FM_GLOBAL float* img, float rx, float ry, float rz, float s) {
  float u, v;
  int ok = fm_warp_project_ray(cam, pose, rx, ry, rz, s, &u, &v);
  return fm_sample_bilinear(img, cam->width, cam->height, ok ? u : -1.0f, ok ? v : -1.0f);
}

/* Cost from the window sums of the warped view W and reference R over n
 * pixels: sw = sum W, sww = sum W^2, swr = sum W R; mean_r, std_r of R over
 * the same window. */
FM_FN float fm_zncc_cost(float n, float sw, float sww, float swr, float mean_r, float std_r) {
  float inv_n = 1.0f / n; /* one division, hoisted out of pixel loops */
  float mean_w = sw * inv_n;
  float var_w = fm_maxf(sww * inv_n - mean_w * mean_w, 0.0f);
  float denom = fm_maxf(FM_SQRT(var_w) * std_r, 1e-12f);
  float zncc = fm_clampf((swr * inv_n - mean_w * mean_r) / denom, -1.0f, 1.0f);
  int textured = (std_r >= FM_MIN_WINDOW_STD ? 1 : 0) & (var_w >= FM_MIN_WINDOW_STD * FM_MIN_WINDOW_STD ? 1 : 0);
  return textured ? 0.5f * (1.0f - zncc) : FM_COST_INVALID;
}

/* Aggregates the per-view costs (FM_COST_INVALID = view unusable here): the
 * mean of the valid ones, or (best-k, occlusion-robust: a view that cannot
 * see the point does not spoil the others) the mean of the min(k, valid)
 * smallest. Invalid when no view is valid. Branch-free per pixel: ranks by
 * pairwise comparison (ties broken by view index); the one branch is on the
 * mode, the same for every pixel (and folded away where it is a constant). */
/* The mean aggregation one view at a time, for backends that produce the
 * views' costs one after another: fm_aggregate_add each view's cost (in view
 * order), then fm_aggregate_mean; the same result as fm_aggregate's mean. */
FM_FN void fm_aggregate_add(float cost, float* sum, int* n) {
  int valid = cost < FM_COST_INVALID;
  *n += valid;
  *sum += valid ? cost : 0.0f;
}

FM_FN float fm_aggregate_mean(float sum, int n) { return n > 0 ? sum / (float)n : FM_COST_INVALID; }

FM_FN float fm_aggregate(const float* costs, int views, int mode, int k) {
  int n = 0;
  float sum_all = 0.0f;
  for (int v = 0; v < views; ++v) {
    fm_aggregate_add(costs[v], &sum_all, &n);
  }
  if (mode != FM_AGGREGATE_BEST_K) { /* the same for every pixel */
    return fm_aggregate_mean(sum_all, n);
  }
  int take = k < n ? k : n;
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

/* Winner-takes-all over the cost volume of one pixel, in three steps that
 * fm_select_plane chains for one pixel (OpenCL, reference) and the native
 * CPU backend runs plane by plane over many pixels at once:
 *   1. best = the plane of lowest cost (first one on ties), cb its cost;
 *   2. fm_select_refine: the best plane's neighbours of the same family
 *      (prev, next; -1 where none), the interval [lo, hi] of ranges they span
 *      along the ray, and the range of the best plane refined (when
 *      `subpixel`) by the vertex of the parabola through the costs of the
 *      best plane and its two neighbours: inverse depth is interpolated for
 *      fronto-parallel and wall planes (uniform in inverse depth / inverse
 *      lateral offset), the plane's offset for ground planes (uniform in
 *      height);
 *   3. second = the lowest cost among the planes fm_select_second_candidate
 *      accepts: not the best or its neighbours, and whose range lies outside
 *      [lo, hi] (so a plane of the other family through the same point does
 *      not count); ratio = best / second in [0, 1] (0 = unique). */
FM_FN float fm_select_refine(const FM_GLOBAL float* volume, int stride, const FM_GLOBAL struct FmSweepPlane* planes,
                             int n_planes, int best, float cb, float rx, float ry, float rz, int subpixel, int* prev_out,
                             int* next_out, float* lo_out, float* hi_out) {
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
      if (pb.family != FM_FAMILY_GROUND) {
        d = 1.0f / (1.0f / pb.d + a * (1.0f / d_other - 1.0f / pb.d));
      } else {
        d = pb.d + a * (d_other - pb.d);
      }
    }
  }
  pb.d = d;
  *prev_out = prev;
  *next_out = next;
  *lo_out = lo;
  *hi_out = hi;
  return fm_plane_range(pb, rx, ry, rz);
}

/* Whether plane j (range t along the ray) may be the second best. */
FM_FN int fm_select_second_candidate(int j, int best, int prev, int next, float t, float lo, float hi) {
  return (j != best ? 1 : 0) & (j != prev ? 1 : 0) & (j != next ? 1 : 0) & (1 - ((t >= lo ? 1 : 0) & (t <= hi ? 1 : 0)));
}

/* Best / second-best cost ratio. */
FM_FN float fm_select_ratio(float cb, float second) {
  return second < FM_COST_INVALID ? (second > 0.0f ? cb / second : 1.0f) : 0.0f;
}

/* The three steps for one pixel (cost of plane j at volume[j * stride]),
 * with the unit ray r of the pixel. Returns 1 and writes the refined range,
 * the best cost and the ratio; returns 0 when no plane has a valid cost (or
 * the refined range is not positive). */
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
  int prev, next;
  float lo, hi;
  float t_best = fm_select_refine(volume, stride, planes, n_planes, best, cb, rx, ry, rz, subpixel, &prev, &next,
                                  &lo, &hi);
  float second = FM_COST_INVALID;
  for (int j = 0; j < n_planes; ++j) {
    float c = volume[j * stride];
    if (!(c < second)) {
      continue;
    }
    if (fm_select_second_candidate(j, best, prev, next, fm_plane_range(planes[j], rx, ry, rz), lo, hi)) {
      second = c;
    }
  }
  *range = t_best;
  *best_cost = cb;
  *ratio = fm_select_ratio(cb, second);
  return *range > 0.0f;
}

#ifndef FM_OPENCL
}  // namespace fisheye_mapping
#endif

#endif /* FISHEYE_MAPPING_CORE_DEPTH_PLANE_SWEEP_SHARED_H_ */
