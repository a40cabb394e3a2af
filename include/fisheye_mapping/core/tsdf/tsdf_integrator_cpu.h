// CPU TSDF integration: an OpenMP loop over the touched blocks (dynamic
// schedule, four blocks a chunk); each block's 512 voxels go through
// fm_tsdf_voxel_pixel and fm_tsdf_fuse (tsdf_shared.h, the OpenCL kernel's
// functions) in vectorized loops (tsdf_integrator_cpu_impl.h, built for the
// baseline, AVX2 and AVX-512; the best the CPU has runs). Threads:
// TsdfConfig::threads as the loop's num_threads clause (0: the OpenMP
// default); the process-wide OpenMP settings are left alone. Not thread-safe
// (see TsdfIntegrator).
#ifndef FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_CPU_H_
#define FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_CPU_H_

#include <vector>

#include "fisheye_mapping/core/tsdf/tsdf_integrator.h"

namespace fisheye_mapping {

class TsdfIntegratorCpu : public TsdfIntegrator {
 public:
  explicit TsdfIntegratorCpu(const TsdfConfig& config);
  TsdfIntegratorKind kind() const override { return TsdfIntegratorKind::kCpu; }
  void integrate(const BlockWork& blocks, const cv::Mat& depth, const cv::Mat& grey, const FmCameraT<float>& camera,
                 const float T_C_W[12], float obs_weight, std::vector<char>* changed) override;

 private:
  float voxel_size_, mu_, max_weight_;  // metres, metres, observations
  int threads_;                         // 0: the OpenMP default at each call
};

// Allocation samples of one image row for TsdfMap::integrate, in the best
// instruction set the CPU has (rowBlockSamples in tsdf_integrator_cpu_impl.h):
// for each pixel u of the row with a measurement and a ray, the blocks of
// n_steps points spread evenly over [max(d - mu, 0), d + mu] along its ray.
// depth: w ranges; rays: 3 w floats (unit rays, NaN outside the domain);
// R_W_C: row-major 3x3, t_W_C: 3 (camera to world); scratch: 5 w floats;
// keys: 3 n_steps w ints, block coordinate a of step s at keys[(3 s + a) w + u];
// valid: w ints, 0 where the pixel has no samples.
void tsdfRowBlockSamples(const float* depth, const float* rays, int w, const float R_W_C[9], const float t_W_C[3],
                         float mu, float inv_block, int n_steps, float* scratch, int* keys, int* valid);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_CPU_H_
