// CPU TSDF integration: an OpenMP loop over the touched blocks (dynamic
// schedule, four blocks a chunk), calling fm_tsdf_integrate_voxel
// (tsdf_shared.h) for each voxel. Threads: TsdfConfig::threads as the loop's
// num_threads clause (0: the OpenMP default); the process-wide OpenMP
// settings are left alone. Not thread-safe (see TsdfIntegrator).
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
                 const float T_C_W[12], std::vector<char>* changed) override;

 private:
  float voxel_size_, mu_, max_weight_;  // metres, metres, observations
  int threads_;                         // 0: the OpenMP default at each call
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_CPU_H_
