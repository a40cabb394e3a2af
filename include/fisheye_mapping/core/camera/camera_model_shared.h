/*
 * Camera models written once, for C++17 and OpenCL C 1.2.
 *
 * This header holds plain functions over a POD parameter struct. C++ includes it
 * through camera_model.h and instantiates the functions for double (the API)
 * and float (to mirror the kernels); OpenCL programs are built from this file's
 * text followed by the kernel's text, so a kernel calls exactly this code.
 *
 * Conventions (all models):
 *   - camera frame: x right, y down, z along the optical axis;
 *   - pixel (u, v): u = fx * mx + skew * my + cx, v = fy * my + cy, where (mx, my)
 *     is the model's (distorted) normalized point; pixel centres are integers;
 *   - fm_project returns 1 iff the point lies in the model's valid domain;
 *     it does NOT check the image bounds (see fm_in_image);
 *   - fm_unproject returns 1 and a UNIT ray iff the pixel is in the domain.
 *
 * Models (FM_MODEL_*):
 *   PINHOLE        radial-tangential (k1 k2 p1 p2) on (x/z, y/z); valid iff z > 0.
 *   UNIFIED        Mei: m = (x, y) / (z + xi d), d = |X|, then radtan.
 *                  Valid iff z > -w d, w = xi (xi <= 1) or 1/xi (xi > 1);
 *                  unprojection valid iff xi <= 1 or r^2 <= 1/(xi^2 - 1).
 *   DOUBLE_SPHERE  Usenko et al. 2018 (xi, alpha), no distortion.
 *   KANNALA_BRANDT equidistant: theta_d = theta (1 + k1 t^2 + k2 t^4 + k3 t^6 + k4 t^8)
 *                  with theta the angle off the axis; valid iff theta <= max_theta.
 * Radial-tangential models are also limited to r^2 <= max_r2, the range where
 * the radial distortion is monotonic (so that it can be inverted); both limits
 * are derived from the coefficients on the host (camera_model.cpp).
 */
#ifndef FISHEYE_MAPPING_CORE_CAMERA_CAMERA_MODEL_SHARED_H_
#define FISHEYE_MAPPING_CORE_CAMERA_CAMERA_MODEL_SHARED_H_

#if defined(__OPENCL_C_VERSION__) || defined(__OPENCL_VERSION__)
/* ---- OpenCL C: single precision, no templates --------------------------- */
#define FM_OPENCL 1
#define FM_FN
#define FM_T_DECL
#define FM_GLOBAL __global
#define FM_CAM struct FmCameraT
#define FM_CAM_FLOAT struct FmCameraT
/* Address space of camera parameter pointers: private by default; a program
 * may build with -DFM_CAM_SPACE=__global to read the parameters in place. */
#ifndef FM_CAM_SPACE
#define FM_CAM_SPACE
#endif
#define FM_SQRT(x) sqrt(x)
#define FM_ATAN2(y, x) atan2(y, x)
#define FM_SIN(x) sin(x)
#define FM_COS(x) cos(x)
#define FM_FABS(x) fabs(x)
typedef float fm_real;
#else
/* ---- C++: the same functions as templates over the scalar type ---------- */
#include <cmath>
/* Always inlined: the native sweep vectorizes loops that call these. */
#define FM_FN inline __attribute__((always_inline))
#define FM_T_DECL template <typename fm_real>
#define FM_GLOBAL
#define FM_CAM FmCameraT<fm_real>
#define FM_CAM_FLOAT FmCameraT<float> /* for functions that exist in float only */
#define FM_CAM_SPACE
#define FM_SQRT(x) std::sqrt(x)
#define FM_ATAN2(y, x) std::atan2(y, x)
#define FM_SIN(x) std::sin(x)
#define FM_COS(x) std::cos(x)
#define FM_FABS(x) std::fabs(x)
namespace fisheye_mapping {
#endif

#define FM_MODEL_PINHOLE 0
#define FM_MODEL_UNIFIED 1
#define FM_MODEL_DOUBLE_SPHERE 2
#define FM_MODEL_KANNALA_BRANDT 3

/* A program built for one camera model only (-DFM_FIXED_MODEL=FM_MODEL_...)
 * folds the model dispatch away at compile time: straight-line code that
 * vectorizers (PoCL's across work items) can handle. The cameras passed in
 * must then all be of that model. */
#ifdef FM_FIXED_MODEL
#define FM_IS_MODEL(cam, m) (FM_FIXED_MODEL == (m))
#else
#define FM_IS_MODEL(cam, m) ((cam)->model == (m))
#endif

/* Newton iterations used to invert distortions, and the residual (in
 * normalized units) under which an inversion counts as converged. */
#define FM_NEWTON_ITERATIONS 20
#define FM_NEWTON_TOLERANCE 1e-5f

/* Plain old data: four ints, then scalars only (no float3: 16 bytes in
 * OpenCL), so FmCameraT<float> on the host has the kernel's layout. */
FM_T_DECL struct FmCameraT {
  int model;  /* FM_MODEL_* */
  int width;  /* image size in pixels */
  int height;
  int reserved;
  fm_real fx, fy, cx, cy, skew;
  fm_real xi;    /* unified, double sphere */
  fm_real alpha; /* double sphere */
  fm_real k1, k2, k3, k4; /* radtan: k1 k2 radial; Kannala-Brandt: k1..k4 */
  fm_real p1, p2;         /* radtan tangential */
  fm_real max_r2;         /* radtan: largest r^2 of the undistorted point */
  fm_real max_theta;      /* Kannala-Brandt: largest angle off the axis */
};

#ifdef FM_OPENCL
typedef struct FmCameraT FmCamera;
#endif

/* Radial-tangential distortion of the normalized point (x, y). */
FM_T_DECL FM_FN void fm_radtan_distort(const FM_CAM_SPACE FM_CAM* cam, fm_real x, fm_real y,
                                       fm_real* xd, fm_real* yd) {
  fm_real r2 = x * x + y * y;
  fm_real radial = 1.0f + r2 * (cam->k1 + r2 * cam->k2);
  *xd = x * radial + 2.0f * cam->p1 * x * y + cam->p2 * (r2 + 2.0f * x * x);
  *yd = y * radial + cam->p1 * (r2 + 2.0f * y * y) + 2.0f * cam->p2 * x * y;
}

/* Inverts fm_radtan_distort by Newton's method on the 2x2 Jacobian.
 * Returns 1 when the residual falls under FM_NEWTON_TOLERANCE. */
FM_T_DECL FM_FN int fm_radtan_undistort(const FM_CAM_SPACE FM_CAM* cam, fm_real xd, fm_real yd,
                                        fm_real* x_out, fm_real* y_out) {
  fm_real x = xd;
  fm_real y = yd;
  fm_real ex = 0.0f;
  fm_real ey = 0.0f;
  for (int it = 0; it < FM_NEWTON_ITERATIONS; ++it) {
    fm_real fx_, fy_;
    fm_radtan_distort(cam, x, y, &fx_, &fy_);
    ex = fx_ - xd;
    ey = fy_ - yd;
    fm_real r2 = x * x + y * y;
    fm_real radial = 1.0f + r2 * (cam->k1 + r2 * cam->k2);
    fm_real dradial_dr2 = cam->k1 + 2.0f * cam->k2 * r2;
    fm_real j00 = radial + 2.0f * x * x * dradial_dr2 + 2.0f * cam->p1 * y + 6.0f * cam->p2 * x;
    fm_real j01 = 2.0f * x * y * dradial_dr2 + 2.0f * cam->p1 * x + 2.0f * cam->p2 * y;
    fm_real j10 = j01;
    fm_real j11 = radial + 2.0f * y * y * dradial_dr2 + 6.0f * cam->p1 * y + 2.0f * cam->p2 * x;
    fm_real det = j00 * j11 - j01 * j10;
    if (FM_FABS(det) < 1e-12f) {
      break;
    }
    fm_real step_x = (j11 * ex - j01 * ey) / det;
    fm_real step_y = (j00 * ey - j10 * ex) / det;
    x -= step_x;
    y -= step_y;
    if (FM_FABS(step_x) + FM_FABS(step_y) < 1e-15f) {
      break;
    }
  }
  fm_real fx_, fy_;
  fm_radtan_distort(cam, x, y, &fx_, &fy_);
  ex = fx_ - xd;
  ey = fy_ - yd;
  *x_out = x;
  *y_out = y;
  return (ex * ex + ey * ey) < FM_NEWTON_TOLERANCE * FM_NEWTON_TOLERANCE;
}

/* Kannala-Brandt: theta_d as a function of theta, and its derivative. */
FM_T_DECL FM_FN fm_real fm_kb_theta_d(const FM_CAM_SPACE FM_CAM* cam, fm_real theta) {
  fm_real t2 = theta * theta;
  return theta * (1.0f + t2 * (cam->k1 + t2 * (cam->k2 + t2 * (cam->k3 + t2 * cam->k4))));
}

FM_T_DECL FM_FN fm_real fm_kb_dtheta_d(const FM_CAM_SPACE FM_CAM* cam, fm_real theta) {
  fm_real t2 = theta * theta;
  return 1.0f + t2 * (3.0f * cam->k1 + t2 * (5.0f * cam->k2 + t2 * (7.0f * cam->k3 + t2 * 9.0f * cam->k4)));
}

/* Normalized (distorted) point -> pixel. */
FM_T_DECL FM_FN void fm_to_pixel(const FM_CAM_SPACE FM_CAM* cam, fm_real mx, fm_real my, fm_real* u,
                                 fm_real* v) {
  *u = cam->fx * mx + cam->skew * my + cam->cx;
  *v = cam->fy * my + cam->cy;
}

/* Pixel -> normalized (distorted) point. */
FM_T_DECL FM_FN void fm_from_pixel(const FM_CAM_SPACE FM_CAM* cam, fm_real u, fm_real v, fm_real* mx,
                                   fm_real* my) {
  *my = (v - cam->cy) / cam->fy;
  *mx = (u - cam->cx - cam->skew * (*my)) / cam->fx;
}

/* Projects the point (x, y, z) given in the camera frame. Validity is
 * combined with & and the special cases are selects rather than branches, so
 * that a loop over points vectorizes (C++ and OpenCL alike). */
FM_T_DECL FM_FN int fm_project(const FM_CAM_SPACE FM_CAM* cam, fm_real x, fm_real y, fm_real z, fm_real* u,
                               fm_real* v) {
  fm_real mx = 0.0f;
  fm_real my = 0.0f;
  int valid = 1;
  if (FM_IS_MODEL(cam, FM_MODEL_PINHOLE) || FM_IS_MODEL(cam, FM_MODEL_UNIFIED)) {
    fm_real denom;
    if (FM_IS_MODEL(cam, FM_MODEL_PINHOLE)) {
      valid = z > 0.0f;
      denom = z;
    } else {
      fm_real d = FM_SQRT(x * x + y * y + z * z);
      fm_real w = cam->xi <= 1.0f ? cam->xi : 1.0f / cam->xi;
      valid = z > -w * d;
      denom = z + cam->xi * d;
    }
    denom = valid ? denom : 1.0f; /* keep the arithmetic finite; the result is flagged */
    fm_real inv = 1.0f / denom;
    fm_real nx = x * inv;
    fm_real ny = y * inv;
    valid = valid & ((nx * nx + ny * ny) <= cam->max_r2 ? 1 : 0);
    fm_radtan_distort(cam, nx, ny, &mx, &my);
  } else if (FM_IS_MODEL(cam, FM_MODEL_DOUBLE_SPHERE)) {
    fm_real d1 = FM_SQRT(x * x + y * y + z * z);
    fm_real alpha = cam->alpha;
    fm_real w1 = alpha <= 0.5f ? alpha / (1.0f - alpha) : (1.0f - alpha) / alpha;
    fm_real w2 = (w1 + cam->xi) / FM_SQRT(2.0f * w1 * cam->xi + cam->xi * cam->xi + 1.0f);
    fm_real k = cam->xi * d1 + z;
    fm_real d2 = FM_SQRT(x * x + y * y + k * k);
    fm_real norm = alpha * d2 + (1.0f - alpha) * k;
    valid = (z > -w2 * d1 ? 1 : 0) & (norm > 0.0f ? 1 : 0);
    norm = valid ? norm : 1.0f;
    mx = x / norm;
    my = y / norm;
  } else if (FM_IS_MODEL(cam, FM_MODEL_KANNALA_BRANDT)) {
    fm_real r = FM_SQRT(x * x + y * y);
    fm_real theta = FM_ATAN2(r, z);
    valid = (theta <= cam->max_theta ? 1 : 0) & ((r > 0.0f || z > 0.0f) ? 1 : 0);
    fm_real scale = fm_kb_theta_d(cam, theta) / (r > 0.0f ? r : 1.0f);
    mx = r > 0.0f ? x * scale : 0.0f;
    my = r > 0.0f ? y * scale : 0.0f;
  } else {
    valid = 0;
  }
  fm_to_pixel(cam, mx, my, u, v);
  return valid;
}

/* Unprojects the pixel (u, v) to a unit ray (rx, ry, rz) in the camera frame. */
FM_T_DECL FM_FN int fm_unproject(const FM_CAM_SPACE FM_CAM* cam, fm_real u, fm_real v, fm_real* rx,
                                 fm_real* ry, fm_real* rz) {
  fm_real mx, my;
  fm_from_pixel(cam, u, v, &mx, &my);
  fm_real x = 0.0f;
  fm_real y = 0.0f;
  fm_real z = 1.0f;
  int valid = 1;
  if (FM_IS_MODEL(cam, FM_MODEL_PINHOLE) || FM_IS_MODEL(cam, FM_MODEL_UNIFIED)) {
    fm_real nx, ny;
    valid = fm_radtan_undistort(cam, mx, my, &nx, &ny);
    fm_real r2 = nx * nx + ny * ny;
    valid = valid && r2 <= cam->max_r2;
    if (FM_IS_MODEL(cam, FM_MODEL_PINHOLE)) {
      x = nx;
      y = ny;
      z = 1.0f;
    } else {
      fm_real xi = cam->xi;
      fm_real disc = 1.0f + (1.0f - xi * xi) * r2;
      valid = valid && (xi <= 1.0f || r2 <= 1.0f / (xi * xi - 1.0f)) && disc >= 0.0f;
      if (disc < 0.0f) {
        disc = 0.0f;
      }
      fm_real factor = (xi + FM_SQRT(disc)) / (1.0f + r2);
      x = factor * nx;
      y = factor * ny;
      z = factor - xi;
    }
  } else if (FM_IS_MODEL(cam, FM_MODEL_DOUBLE_SPHERE)) {
    fm_real alpha = cam->alpha;
    fm_real xi = cam->xi;
    fm_real r2 = mx * mx + my * my;
    fm_real disc1 = 1.0f - (2.0f * alpha - 1.0f) * r2;
    valid = (alpha <= 0.5f || r2 <= 1.0f / (2.0f * alpha - 1.0f)) && disc1 >= 0.0f;
    if (disc1 < 0.0f) {
      disc1 = 0.0f;
    }
    fm_real mz = (1.0f - alpha * alpha * r2) / (alpha * FM_SQRT(disc1) + 1.0f - alpha);
    fm_real disc2 = mz * mz + (1.0f - xi * xi) * r2;
    valid = valid && disc2 >= 0.0f;
    if (disc2 < 0.0f) {
      disc2 = 0.0f;
    }
    fm_real k = (mz * xi + FM_SQRT(disc2)) / (mz * mz + r2);
    x = k * mx;
    y = k * my;
    z = k * mz - xi;
  } else if (FM_IS_MODEL(cam, FM_MODEL_KANNALA_BRANDT)) {
    fm_real theta_d = FM_SQRT(mx * mx + my * my);
    if (theta_d > 0.0f) {
      fm_real theta = theta_d;
      for (int it = 0; it < FM_NEWTON_ITERATIONS; ++it) {
        fm_real f = fm_kb_theta_d(cam, theta) - theta_d;
        fm_real df = fm_kb_dtheta_d(cam, theta);
        if (!(df > 0.0f)) {
          break;
        }
        fm_real step = f / df;
        theta -= step;
        if (FM_FABS(step) < 1e-15f) {
          break;
        }
      }
      fm_real residual = fm_kb_theta_d(cam, theta) - theta_d;
      valid = theta >= 0.0f && theta <= cam->max_theta && FM_FABS(residual) < FM_NEWTON_TOLERANCE;
      fm_real s = FM_SIN(theta) / theta_d;
      x = s * mx;
      y = s * my;
      z = FM_COS(theta);
    }
  } else {
    valid = 0;
  }
  fm_real n = FM_SQRT(x * x + y * y + z * z);
  if (!(n > 0.0f)) {
    n = 1.0f;
    valid = 0;
  }
  *rx = x / n;
  *ry = y / n;
  *rz = z / n;
  return valid;
}

/* 1 iff the pixel lies inside the image, at least `margin` pixels from the
 * border of the area covered by pixel centres [0, width-1] x [0, height-1]. */
FM_T_DECL FM_FN int fm_in_image(const FM_CAM_SPACE FM_CAM* cam, fm_real u, fm_real v, fm_real margin) {
  return u >= margin && v >= margin && u <= (fm_real)(cam->width - 1) - margin &&
         v <= (fm_real)(cam->height - 1) - margin;
}

#ifndef FM_OPENCL
}  // namespace fisheye_mapping
#endif

#endif /* FISHEYE_MAPPING_CORE_CAMERA_CAMERA_MODEL_SHARED_H_ */
