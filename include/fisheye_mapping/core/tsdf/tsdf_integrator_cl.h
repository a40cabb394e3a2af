// OpenCL integration of the voxels of the blocks a frame touched: the same
// per-voxel function as the C++ loop (tsdf_shared.h), one work item per voxel.
// Buffers are kept and grown frame to frame; the program is built once.
// Not thread-safe.
#ifndef FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_CL_H_
#define FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_CL_H_

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "fisheye_mapping/core/common/opencl_context.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"

namespace fisheye_mapping {

class TsdfIntegratorCl {
 public:
  // device: as OpenClContext. Throws OpenClError when no device matches.
  explicit TsdfIntegratorCl(const std::string& device = "");
  const std::string& deviceName() const { return ctx_.deviceName(); }

  // Integrates `depth` (CV_32FC1, continuous) into the given blocks; sets
  // changed[n] for each block whose voxels changed.
  void integrate(const std::vector<std::pair<BlockIndex, VoxelBlock*>>& blocks, const cv::Mat& depth,
                 const FmCameraT<float>& camera, const float T_C_W[12], float voxel_size, float mu,
                 float max_weight, std::vector<char>* changed);

 private:
  void reserve(cl::Buffer* buffer, size_t* capacity, size_t bytes, cl_mem_flags flags);

  OpenClContext ctx_;
  cl::Kernel kernel_;
  cl::Buffer voxels_, coords_, depth_, camera_, pose_, changed_;
  size_t voxels_cap_ = 0, coords_cap_ = 0, depth_cap_ = 0, changed_cap_ = 0;
  std::vector<FmVoxel> staging_;
  std::vector<int> coords_host_, changed_host_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_CL_H_
