/*
 * TSDF voxel and its update, written once for C++ and OpenCL C (like
 * camera_model_shared.h, whose macros it uses). Include camera_model_shared.h
 * first.
 *
 * A voxel stores D, the truncated signed distance divided by the truncation
 * mu (so D lies in [-1, 1], positive in front of the surface), and w, the
 * number of observations fused so far, capped at a maximum. Beside each
 * voxel (in VoxelBlock::grey, not in FmVoxel, so that the map's memory grows
 * by an eighth and not by half), its intensity: the grey value of the pixels
 * fused into it, averaged with the voxel's weight (capped at
 * FM_GREY_MAX_WEIGHT, so that it follows the newest views), as 1..255;
 * 0 = none yet (never seen by an image, or a map file from before the
 * intensity channel).
 */
#ifndef FISHEYE_MAPPING_CORE_TSDF_TSDF_SHARED_H_
#define FISHEYE_MAPPING_CORE_TSDF_TSDF_SHARED_H_

#ifndef FM_OPENCL
namespace fisheye_mapping {
#endif

#define FM_BLOCK_SIDE 8
#define FM_BLOCK_VOXELS 512
/* Cap of the weight that averages a voxel's intensity (rounded to 1..255). */
#define FM_GREY_MAX_WEIGHT 16.0f

struct FmVoxel {
  float tsdf;   /* D in [-1, 1] */
  float weight; /* observations, capped at max_weight; 0 = never observed */
};

#ifdef FM_OPENCL
typedef struct FmVoxel FmVoxel;
#endif

/* Fuses one observation: eta = measured range - the voxel's range along the
 * same ray. Nothing happens behind the surface (eta < -mu). Otherwise
 * D <- (w D + min(1, eta / mu)) / (w + 1) and w <- min(w + 1, max_weight).
 * Returns 1 if the voxel changed. */
FM_FN int fm_tsdf_update(FM_GLOBAL struct FmVoxel* v, float eta, float mu, float max_weight) {
  if (!(eta >= -mu)) {
    return 0;
  }
  float d = eta / mu;
  if (d > 1.0f) {
    d = 1.0f;
  }
  const float w = v->weight;
  v->tsdf = (w * v->tsdf + d) / (w + 1.0f);
  v->weight = (w + 1.0f < max_weight) ? w + 1.0f : max_weight;
  return 1;
}

/* Averages the grey value g (0..255) of an observation into a voxel's
 * intensity *grey (0 = none yet) whose TSDF weight before this observation was
 * w: *grey <- round((w' *grey + g) / (w' + 1)), w' = min(w, FM_GREY_MAX_WEIGHT);
 * the first observation (or *grey == 0) sets it to round(g); always >= 1. */
FM_FN void fm_grey_update(FM_GLOBAL unsigned char* grey, float w, float g) {
  float wg = (w < FM_GREY_MAX_WEIGHT) ? w : FM_GREY_MAX_WEIGHT;
  if (*grey == 0) {
    wg = 0.0f;
  }
  float value = (wg * (float)(*grey) + g) / (wg + 1.0f) + 0.5f;
  if (value < 1.0f) {
    value = 1.0f;
  }
  if (value > 255.0f) {
    value = 255.0f;
  }
  *grey = (unsigned char)value;
}

/* The pixel whose measurement a voxel takes: the nearest pixel to the
 * projection of the voxel's centre (x, y, z), given in the camera frame, as
 * row * width + column; -1 when the centre is outside the model's domain or
 * the image. Branch-free (selects), so that a loop over voxels vectorizes; the
 * projection is clamped to the image before the conversion to int, so that the
 * conversion is defined for any point. */
FM_FN int fm_tsdf_voxel_pixel(const FM_CAM_FLOAT* cam, float x, float y, float z) {
  float u, vv;
  int ok = fm_project(cam, x, y, z, &u, &vv);
  const float w = (float)cam->width;
  const float h = (float)cam->height;
  ok = ok & (u >= -0.5f ? 1 : 0) & (vv >= -0.5f ? 1 : 0) & (u < w ? 1 : 0) & (vv < h ? 1 : 0);
  u = ok ? u : 0.0f;
  vv = ok ? vv : 0.0f;
  /* nearest pixel */
  const int iu = (int)(u + 0.5f);
  const int iv = (int)(vv + 0.5f);
  ok = ok & (iu < cam->width ? 1 : 0) & (iv < cam->height ? 1 : 0);
  return ok ? iv * cam->width + iu : -1;
}

/* Fuses one pixel's measurement into a voxel: measured is the pixel's range
 * along its ray (NaN, inf or non-positive: none), range the voxel centre's
 * distance from the camera, g the pixel's grey value (0..255; negative: no
 * image), a > 0 the frame's observation weight (1: a full observation).
 * eta = measured - range is fused by fm_tsdf_update's rule weighted by a:
 * D <- (w D + a min(1, eta / mu)) / (w + a), w <- min(w + a, max_weight)
 * (with a = 1 exactly fm_tsdf_update), and a voxel within the truncation
 * band of the surface (|eta| <= mu) takes g into *grey (fm_grey_update). The
 * same arithmetic as those two, written with selects and unconditional
 * stores of the kept value, so that a loop over a block's voxels vectorizes.
 * Returns 1 if the voxel changed. */
FM_FN int fm_tsdf_fuse(FM_GLOBAL struct FmVoxel* v, FM_GLOBAL unsigned char* grey, float measured, float range,
                       float g, float mu, float max_weight, float a) {
  const float eta = measured - range;
  /* a measurement (not NaN, inf or <= 0), and the voxel not behind the band */
  const int ok = (measured > 0.0f ? 1 : 0) & (measured <= 1e30f ? 1 : 0) & (eta >= -mu ? 1 : 0);
  float d = eta / mu;
  d = d > 1.0f ? 1.0f : d;
  const float w = v->weight;
  const float t = v->tsdf;
  const float t_new = (w * t + a * d) / (w + a);
  const float w_new = (w + a < max_weight) ? w + a : max_weight;
  v->tsdf = ok ? t_new : t;
  v->weight = ok ? w_new : w;
  const int old_grey = (int)(*grey);
  float wg = (w < FM_GREY_MAX_WEIGHT) ? w : FM_GREY_MAX_WEIGHT;
  wg = old_grey == 0 ? 0.0f : wg;
  float value = (wg * (float)old_grey + g) / (wg + 1.0f) + 0.5f;
  value = value < 1.0f ? 1.0f : value;
  value = value > 255.0f ? 255.0f : value;
  const int take_grey = ok & (g >= 0.0f ? 1 : 0) & (eta <= mu ? 1 : 0);
  *grey = (unsigned char)(take_grey ? (int)value : old_grey);
  return ok;
}

/* Integrates the depth map into one voxel whose centre is p_W (world frame).
 * T_C_W is row-major 3x4 (rotation | translation) mapping world to camera.
 * depth: row-major, width x height metres of range along the ray, NaN invalid.
 * image: the same camera's grey image (width x height bytes, row-major), or
 * 0 (no intensity). a: the frame's observation weight (fm_tsdf_fuse).
 * fm_tsdf_voxel_pixel, then fm_tsdf_fuse (the OpenCL
 * kernel's per-voxel work; the CPU integrator runs the same two functions in
 * vectorized loops over a block). */
FM_FN int fm_tsdf_integrate_voxel(FM_GLOBAL struct FmVoxel* v, FM_GLOBAL unsigned char* grey, float px, float py,
                                  float pz, const FM_CAM_FLOAT* cam, const float* T_C_W,
                                  FM_GLOBAL const float* depth, FM_GLOBAL const unsigned char* image, float mu,
                                  float max_weight, float a) {
  const float x = T_C_W[0] * px + T_C_W[1] * py + T_C_W[2] * pz + T_C_W[3];
  const float y = T_C_W[4] * px + T_C_W[5] * py + T_C_W[6] * pz + T_C_W[7];
  const float z = T_C_W[8] * px + T_C_W[9] * py + T_C_W[10] * pz + T_C_W[11];
  const int pixel = fm_tsdf_voxel_pixel(cam, x, y, z);
  if (pixel < 0) {
    return 0;
  }
  const float g = image ? (float)image[pixel] : -1.0f;
  return fm_tsdf_fuse(v, grey, depth[pixel], FM_SQRT(x * x + y * y + z * z), g, mu, max_weight, a);
}

#ifndef FM_OPENCL
}  // namespace fisheye_mapping
#endif

#endif /* FISHEYE_MAPPING_CORE_TSDF_TSDF_SHARED_H_ */
