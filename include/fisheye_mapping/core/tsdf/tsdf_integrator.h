// Voxel integration backends of the TSDF map (like the sweep's SweepBackend):
// given the blocks a frame touched (allocated by the BlockStore), fuse the
// depth map into every voxel of them with the per-voxel update of
// tsdf_shared.h, which both backends share:
//   TsdfIntegratorCpu (tsdf_integrator_cpu.h): an OpenMP loop over the blocks;
//   TsdfIntegratorCl  (tsdf_integrator_cl.h): the same function as an OpenCL
//                     kernel, one work item per voxel.
// The voxel size, truncation, weight cap (and threads, for the CPU) come from
// the TsdfConfig the backend was made with.
#ifndef FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_H_
#define FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_H_

#include <memory>
#include <vector>

#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/camera_model.h"
#include "fisheye_mapping/core/tsdf/block_store.h"
#include "fisheye_mapping/core/tsdf/tsdf_config.h"

namespace fisheye_mapping {

class TsdfIntegrator {
 public:
  virtual ~TsdfIntegrator() = default;
  virtual TsdfIntegratorKind kind() const = 0;

  // Fuses `depth` into every voxel of `blocks` and sets (*changed)[n] (resized
  // to blocks.size()) to 1 for each block whose voxels changed, 0 otherwise.
  //   depth: CV_32FC1, continuous, the camera's size; metres of range along
  //          each pixel's ray; NaN, inf or <= 0 where there is none.
  //   grey: CV_8UC1, continuous, the camera's size (the image the depth was
  //         computed for), averaged into the intensity of the voxels near the
  //         surface; empty: no intensity (the voxels' grey stays as it is).
  //   camera: the depth map's camera model (float parameters).
  //   T_C_W: row-major 3x4 [R | t] from the world frame to the camera frame
  //          (metres).
  //   obs_weight: the frame's observation weight, > 0 (fm_tsdf_fuse's a; 1: a
  //          full observation).
  // Voxel centres are (global voxel index + 0.5) * voxel_size in the world
  // frame. Not thread-safe (one call at a time per integrator); the blocks'
  // storage must not be touched by anything else during the call. The CPU
  // backend uses config.threads threads (0: the OpenMP default).
  virtual void integrate(const BlockWork& blocks, const cv::Mat& depth, const cv::Mat& grey,
                         const FmCameraT<float>& camera, const float T_C_W[12], float obs_weight, std::vector<char>* changed) = 0;
};

// The backend config.integrator names. Throws std::invalid_argument for an
// unknown name, OpenClError when "opencl" finds no matching device.
std::unique_ptr<TsdfIntegrator> makeTsdfIntegrator(const TsdfConfig& config);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_TSDF_INTEGRATOR_H_
