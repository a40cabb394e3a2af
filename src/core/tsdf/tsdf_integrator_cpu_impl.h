// The CPU TSDF integrator's loops over one block (see tsdf_integrator_cpu.cpp).
// No include guard on purpose: tsdf_integrator_cpu.cpp includes this file once
// per instruction set, inside a namespace of its own (tsdf_generic, tsdf_avx2,
// tsdf_avx512), with the target set by a pragma around the include. The
// per-voxel maths are the shared functions of tsdf_shared.h (the OpenCL kernel
// calls the same ones); what is here is the loop structure: the block's 512
// voxels projected in one loop the compiler vectorizes, the depth and grey of
// their pixels loaded by plain scalar loads (on CPUs they beat gathers), and
// the updates applied in a second vectorized loop. BlockScratch (each thread's
// arrays for one block) is defined once, before the includes.

// Integrates the depth (and grey) image into the block whose first voxel's
// corner is origin (in voxels); returns whether any voxel changed. The camera
// model is a template argument so that its dispatch folds away.
template <int MODEL>
TSDF_INLINE bool integrateBlockT(FmVoxel* __restrict voxels, unsigned char* __restrict greys, const float origin[3],
                                 float vs, FmCameraT<float> cam, const float* __restrict T,
                                 const float* __restrict depth, const unsigned char* __restrict image, float mu,
                                 float max_weight, float a, BlockScratch* __restrict s) {
  cam.model = MODEL;
  const float ox = origin[0] + 0.5f, oy = origin[1] + 0.5f, oz = origin[2] + 0.5f;
  int seen = 0;
#pragma omp simd reduction(| : seen)
  for (int l = 0; l < FM_BLOCK_VOXELS; ++l) {
    const float px = (ox + static_cast<float>(l % FM_BLOCK_SIDE)) * vs;
    const float py = (oy + static_cast<float>((l / FM_BLOCK_SIDE) % FM_BLOCK_SIDE)) * vs;
    const float pz = (oz + static_cast<float>(l / (FM_BLOCK_SIDE * FM_BLOCK_SIDE))) * vs;
    const float x = T[0] * px + T[1] * py + T[2] * pz + T[3];
    const float y = T[4] * px + T[5] * py + T[6] * pz + T[7];
    const float z = T[8] * px + T[9] * py + T[10] * pz + T[11];
    const int p = fm_tsdf_voxel_pixel(&cam, x, y, z);
    s->pixel[l] = p;
    s->range[l] = std::sqrt(x * x + y * y + z * z);
    seen |= p >= 0 ? 1 : 0;
  }
  if (!seen) return false;  // the whole block outside the image
  const float none = std::numeric_limits<float>::quiet_NaN();
  for (int l = 0; l < FM_BLOCK_VOXELS; ++l) {
    const int p = s->pixel[l];
    s->measured[l] = p >= 0 ? depth[p] : none;
    s->grey[l] = image && p >= 0 ? static_cast<float>(image[p]) : -1.0f;
  }
  int any = 0;
#pragma omp simd reduction(| : any)
  for (int l = 0; l < FM_BLOCK_VOXELS; ++l) {
    any |= fm_tsdf_fuse(&voxels[l], &greys[l], s->measured[l], s->range[l], s->grey[l], mu, max_weight, a);
  }
  return any != 0;
}

inline bool integrateBlock(FmVoxel* voxels, unsigned char* greys, const float origin[3], float vs,
                           const FmCameraT<float>& cam, const float* T, const float* depth,
                           const unsigned char* image, float mu, float max_weight, float a, BlockScratch* s) {
  switch (cam.model) {
    case FM_MODEL_UNIFIED:
      return integrateBlockT<FM_MODEL_UNIFIED>(voxels, greys, origin, vs, cam, T, depth, image, mu, max_weight, a, s);
    case FM_MODEL_PINHOLE:
      return integrateBlockT<FM_MODEL_PINHOLE>(voxels, greys, origin, vs, cam, T, depth, image, mu, max_weight, a, s);
    case FM_MODEL_DOUBLE_SPHERE:
      return integrateBlockT<FM_MODEL_DOUBLE_SPHERE>(voxels, greys, origin, vs, cam, T, depth, image, mu, max_weight, a,
                                                     s);
    case FM_MODEL_KANNALA_BRANDT:
      return integrateBlockT<FM_MODEL_KANNALA_BRANDT>(voxels, greys, origin, vs, cam, T, depth, image, mu,
                                                      max_weight, a, s);
    default:
      return false;
  }
}

// Allocation samples of one image row (TsdfMap::integrate, step 1): for each
// pixel u with a measurement d (finite, > 0) and a ray (rays: unit rays, 3
// floats a pixel, NaN outside the model's domain), the block of each of
// n_steps points spread evenly over [max(d - mu, 0), d + mu] along the ray in
// the world frame (R, t: camera to world; R row-major). Written to
// keys[(3 s + axis) * w + u]; valid[u] says whether the pixel has samples.
// Block coordinates are clamped to +-2^30 before the conversion to int (NaN
// to -2^30). scratch: 5 w floats.
inline void rowBlockSamples(const float* __restrict depth, const float* __restrict rays, int w,
                            const float* __restrict R, const float* __restrict t, float mu, float inv_block,
                            int n_steps, float* __restrict scratch, int* __restrict keys,
                            int* __restrict valid) {
  float* __restrict dx = scratch;
  float* __restrict dy = scratch + w;
  float* __restrict dz = scratch + 2 * w;
  float* __restrict start = scratch + 3 * w;
  float* __restrict length = scratch + 4 * w;
#pragma omp simd
  for (int u = 0; u < w; ++u) {
    const float d = depth[u];
    const float rx = rays[3 * u], ry = rays[3 * u + 1], rz = rays[3 * u + 2];
    valid[u] = (d > 0.0f ? 1 : 0) & (d <= 1e30f ? 1 : 0) & (rz == rz ? 1 : 0);
    dx[u] = R[0] * rx + R[1] * ry + R[2] * rz;
    dy[u] = R[3] * rx + R[4] * ry + R[5] * rz;
    dz[u] = R[6] * rx + R[7] * ry + R[8] * rz;
    const float s0 = d - mu > 0.0f ? d - mu : 0.0f;
    start[u] = s0;
    length[u] = d + mu - s0;
  }
  const float limit = 1073741824.0f;  // 2^30
  for (int s = 0; s < n_steps; ++s) {
    const float f = static_cast<float>(s) / static_cast<float>(n_steps - 1);
    int* __restrict kx = keys + (3 * s) * w;
    int* __restrict ky = keys + (3 * s + 1) * w;
    int* __restrict kz = keys + (3 * s + 2) * w;
#pragma omp simd
    for (int u = 0; u < w; ++u) {
      const float r = start[u] + length[u] * f;
      float bx = std::floor((t[0] + r * dx[u]) * inv_block);
      float by = std::floor((t[1] + r * dy[u]) * inv_block);
      float bz = std::floor((t[2] + r * dz[u]) * inv_block);
      bx = bx >= -limit ? (bx <= limit ? bx : limit) : -limit;  // NaN: -limit
      by = by >= -limit ? (by <= limit ? by : limit) : -limit;
      bz = bz >= -limit ? (bz <= limit ? bz : limit) : -limit;
      kx[u] = static_cast<int>(bx);
      ky[u] = static_cast<int>(by);
      kz[u] = static_cast<int>(bz);
    }
  }
}
