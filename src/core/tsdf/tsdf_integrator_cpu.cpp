#include "fisheye_mapping/core/tsdf/tsdf_integrator_cpu.h"

#include <omp.h>

#include <cmath>
#include <limits>
#include <memory>

#include "fisheye_mapping/core/common/cpu_features.h"

namespace fisheye_mapping {

// The block loops, compiled for the x86-64 baseline, AVX2 + FMA and AVX-512
// (as the native sweep's, plane_sweep_native.cpp); chosen at run time.
#define TSDF_INLINE [[gnu::always_inline]] inline
struct BlockScratch {
  alignas(64) int pixel[FM_BLOCK_VOXELS];
  alignas(64) float range[FM_BLOCK_VOXELS];
  alignas(64) float measured[FM_BLOCK_VOXELS];
  alignas(64) float grey[FM_BLOCK_VOXELS];
};
namespace tsdf_generic {
#include "tsdf_integrator_cpu_impl.h"  // NOLINT(build/include)
}  // namespace tsdf_generic

#if defined(__x86_64__) && defined(__GNUC__)
#define FM_TSDF_HAVE_AVX2 1
#pragma GCC push_options
#pragma GCC target("avx2,fma")
namespace tsdf_avx2 {
#include "tsdf_integrator_cpu_impl.h"  // NOLINT(build/include)
}  // namespace tsdf_avx2
#pragma GCC pop_options
#pragma GCC push_options
#pragma GCC target("avx512f,avx512vl,avx512dq,avx512bw,avx2,fma,prefer-vector-width=512")
namespace tsdf_avx512 {
#include "tsdf_integrator_cpu_impl.h"  // NOLINT(build/include)
}  // namespace tsdf_avx512
#pragma GCC pop_options
#endif

void tsdfRowBlockSamples(const float* depth, const float* rays, int w, const float R_W_C[9], const float t_W_C[3],
                         float mu, float inv_block, int n_steps, float* scratch, int* keys, int* valid) {
#ifdef FM_TSDF_HAVE_AVX2
  const SimdLevel simd = cpuSimdLevel();
  if (simd == SimdLevel::kAvx512) {
    tsdf_avx512::rowBlockSamples(depth, rays, w, R_W_C, t_W_C, mu, inv_block, n_steps, scratch, keys, valid);
    return;
  }
  if (simd == SimdLevel::kAvx2) {
    tsdf_avx2::rowBlockSamples(depth, rays, w, R_W_C, t_W_C, mu, inv_block, n_steps, scratch, keys, valid);
    return;
  }
#endif
  tsdf_generic::rowBlockSamples(depth, rays, w, R_W_C, t_W_C, mu, inv_block, n_steps, scratch, keys, valid);
}

TsdfIntegratorCpu::TsdfIntegratorCpu(const TsdfConfig& config)
    : voxel_size_(static_cast<float>(config.voxel_size)),
      mu_(static_cast<float>(config.truncation())),
      max_weight_(config.max_weight),
      threads_(config.threads) {}

void TsdfIntegratorCpu::integrate(const BlockWork& blocks, const cv::Mat& depth_image, const cv::Mat& grey_image,
                                  const FmCameraT<float>& cam,
                                  const float T_C_W[12], float obs_weight, std::vector<char>* changed) {
  const float vs = voxel_size_;
  const float mu = mu_;
  const float max_w = max_weight_;
  const float* depth = depth_image.ptr<float>();
  const unsigned char* image = grey_image.empty() ? nullptr : grey_image.ptr<unsigned char>();
  const int threads = threads_ > 0 ? threads_ : omp_get_max_threads();
  const SimdLevel simd = cpuSimdLevel();
  changed->assign(blocks.size(), 0);
#pragma omp parallel num_threads(threads)
  {
    BlockScratch scratch;
#pragma omp for schedule(dynamic, 4)
    for (size_t n = 0; n < blocks.size(); ++n) {
      const BlockIndex& b = blocks[n].first;
      FmVoxel* voxels = blocks[n].second->voxels.data();
      unsigned char* greys = blocks[n].second->grey.data();
      const float origin[3] = {static_cast<float>(b.x() * FM_BLOCK_SIDE), static_cast<float>(b.y() * FM_BLOCK_SIDE),
                               static_cast<float>(b.z() * FM_BLOCK_SIDE)};
      bool any;
#ifdef FM_TSDF_HAVE_AVX2
      if (simd == SimdLevel::kAvx512) {
        any = tsdf_avx512::integrateBlock(voxels, greys, origin, vs, cam, T_C_W, depth, image, mu, max_w, obs_weight, &scratch);
      } else if (simd == SimdLevel::kAvx2) {
        any = tsdf_avx2::integrateBlock(voxels, greys, origin, vs, cam, T_C_W, depth, image, mu, max_w, obs_weight, &scratch);
      } else
#endif
      {
        (void)simd;
        any = tsdf_generic::integrateBlock(voxels, greys, origin, vs, cam, T_C_W, depth, image, mu, max_w, obs_weight, &scratch);
      }
      (*changed)[n] = static_cast<char>(any);
    }
  }
}

}  // namespace fisheye_mapping
