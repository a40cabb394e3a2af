#include "fisheye_mapping/core/tsdf/tsdf_integrator_cpu.h"

#include <omp.h>

namespace fisheye_mapping {

TsdfIntegratorCpu::TsdfIntegratorCpu(const TsdfConfig& config)
    : voxel_size_(static_cast<float>(config.voxel_size)),
      mu_(static_cast<float>(config.truncation())),
      max_weight_(config.max_weight),
      threads_(config.threads) {}

void TsdfIntegratorCpu::integrate(const BlockWork& blocks, const cv::Mat& depth_image, const cv::Mat& grey_image,
                                  const FmCameraT<float>& cam,
                                  const float T_C_W[12], std::vector<char>* changed) {
  const float vs = voxel_size_;
  const float mu = mu_;
  const float max_w = max_weight_;
  const float* depth = depth_image.ptr<float>();
  const unsigned char* image = grey_image.empty() ? nullptr : grey_image.ptr<unsigned char>();
  const int threads = threads_ > 0 ? threads_ : omp_get_max_threads();
  changed->assign(blocks.size(), 0);
#pragma omp parallel for num_threads(threads) schedule(dynamic, 4)
  for (size_t n = 0; n < blocks.size(); ++n) {
    const BlockIndex& b = blocks[n].first;
    FmVoxel* voxels = blocks[n].second->voxels.data();
    unsigned char* greys = blocks[n].second->grey.data();
    const Eigen::Vector3f origin = (b * FM_BLOCK_SIDE).cast<float>();
    int any = 0;
    for (int k = 0; k < FM_BLOCK_SIDE; ++k) {
      const float pz = (origin.z() + k + 0.5f) * vs;
      for (int j = 0; j < FM_BLOCK_SIDE; ++j) {
        const float py = (origin.y() + j + 0.5f) * vs;
        for (int i = 0; i < FM_BLOCK_SIDE; ++i) {
          const float px = (origin.x() + i + 0.5f) * vs;
          const int l = VoxelBlock::linear(i, j, k);
          any |= fm_tsdf_integrate_voxel(&voxels[l], &greys[l], px, py, pz, &cam, T_C_W, depth, image, mu, max_w);
        }
      }
    }
    (*changed)[n] = static_cast<char>(any);
  }
}

}  // namespace fisheye_mapping
