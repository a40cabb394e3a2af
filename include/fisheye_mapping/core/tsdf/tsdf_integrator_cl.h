// OpenCL TSDF integration: the same per-voxel function as the CPU loop
// (tsdf_shared.h, kernel in tsdf_integrate.cl), one work item per voxel of
// the touched blocks, which are copied to the device and back each frame.
// Buffers are kept and grown frame to frame; the program is built once.
// Not thread-safe (see TsdfIntegrator).
#ifndef FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_CL_H_
#define FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_CL_H_

#include <string>
#include <vector>

#include "fisheye_mapping/core/common/opencl_context.h"
#include "fisheye_mapping/core/tsdf/tsdf_integrator.h"

namespace fisheye_mapping {

class TsdfIntegratorCl : public TsdfIntegrator {
 public:
  // On config.opencl_device (as OpenClContext). Throws OpenClError when no
  // device matches or the program does not build.
  explicit TsdfIntegratorCl(const TsdfConfig& config);
  TsdfIntegratorKind kind() const override { return TsdfIntegratorKind::kOpenCl; }
  const std::string& deviceName() const { return ctx_.deviceName(); }

  void integrate(const BlockWork& blocks, const cv::Mat& depth, const cv::Mat& grey, const FmCameraT<float>& camera,
                 const float T_C_W[12], float obs_weight, std::vector<char>* changed) override;

 private:
  void reserve(cl::Buffer* buffer, size_t* capacity, size_t bytes, cl_mem_flags flags);

  float voxel_size_, mu_, max_weight_;  // metres, metres, observations
  OpenClContext ctx_;
  cl::Kernel kernel_;
  cl::Buffer voxels_, greys_, coords_, depth_, image_, camera_, pose_, changed_;
  size_t voxels_cap_ = 0, greys_cap_ = 0, coords_cap_ = 0, depth_cap_ = 0, image_cap_ = 0, changed_cap_ = 0;
  std::vector<FmVoxel> staging_;
  std::vector<unsigned char> grey_staging_;
  std::vector<int> coords_host_, changed_host_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_CL_H_
