#include "fisheye_mapping/core/tsdf/tsdf_integrator_cl.h"

#include <cstring>

namespace fisheye_mapping {

TsdfIntegratorCl::TsdfIntegratorCl(const TsdfConfig& config)
    : voxel_size_(static_cast<float>(config.voxel_size)),
      mu_(static_cast<float>(config.truncation())),
      max_weight_(config.max_weight),
      ctx_(config.opencl_device) {
  cl::Program& program = ctx_.program(
      {clSource("camera_model_shared.h"), clSource("tsdf_shared.h"), clSource("tsdf_integrate.cl")});
  kernel_ = cl::Kernel(program, "integrate_blocks");
  camera_ = cl::Buffer(ctx_.context(), CL_MEM_READ_ONLY, sizeof(FmCameraT<float>));
  pose_ = cl::Buffer(ctx_.context(), CL_MEM_READ_ONLY, 12 * sizeof(float));
}

void TsdfIntegratorCl::reserve(cl::Buffer* buffer, size_t* capacity, size_t bytes, cl_mem_flags flags) {
  if (bytes <= *capacity) return;
  *capacity = bytes + bytes / 2;
  *buffer = cl::Buffer(ctx_.context(), flags, *capacity);
}

void TsdfIntegratorCl::integrate(const BlockWork& blocks, const cv::Mat& depth, const cv::Mat& grey,
                                 const FmCameraT<float>& camera,
                                 const float T_C_W[12], float obs_weight, std::vector<char>* changed) {
  const size_t n = blocks.size();
  changed->assign(n, 0);
  if (n == 0) return;
  const size_t voxel_bytes = n * sizeof(VoxelBlock::voxels);
  staging_.resize(n * FM_BLOCK_VOXELS);
  grey_staging_.resize(n * FM_BLOCK_VOXELS);
  coords_host_.resize(3 * n);
  changed_host_.assign(n, 0);
  for (size_t b = 0; b < n; ++b) {
    std::memcpy(&staging_[b * FM_BLOCK_VOXELS], blocks[b].second->voxels.data(), sizeof(VoxelBlock::voxels));
    std::memcpy(&grey_staging_[b * FM_BLOCK_VOXELS], blocks[b].second->grey.data(), sizeof(VoxelBlock::grey));
    for (int a = 0; a < 3; ++a) coords_host_[3 * b + a] = blocks[b].first[a];
  }
  reserve(&voxels_, &voxels_cap_, voxel_bytes, CL_MEM_READ_WRITE);
  const bool has_image = !grey.empty();
  const size_t grey_bytes = n * sizeof(VoxelBlock::grey);
  reserve(&greys_, &greys_cap_, grey_bytes, CL_MEM_READ_WRITE);
  // Without an image, a one-byte stand-in (never read: has_image 0).
  reserve(&image_, &image_cap_, has_image ? grey.total() : 1, CL_MEM_READ_ONLY);
  reserve(&coords_, &coords_cap_, coords_host_.size() * sizeof(int), CL_MEM_READ_ONLY);
  reserve(&depth_, &depth_cap_, depth.total() * sizeof(float), CL_MEM_READ_ONLY);
  reserve(&changed_, &changed_cap_, n * sizeof(int), CL_MEM_READ_WRITE);
  cl::CommandQueue& q = ctx_.queue();
  q.enqueueWriteBuffer(voxels_, CL_FALSE, 0, voxel_bytes, staging_.data());
  q.enqueueWriteBuffer(greys_, CL_FALSE, 0, grey_bytes, grey_staging_.data());
  if (has_image) q.enqueueWriteBuffer(image_, CL_FALSE, 0, grey.total(), grey.ptr<unsigned char>());
  q.enqueueWriteBuffer(coords_, CL_FALSE, 0, coords_host_.size() * sizeof(int), coords_host_.data());
  q.enqueueWriteBuffer(depth_, CL_FALSE, 0, depth.total() * sizeof(float), depth.ptr<float>());
  q.enqueueWriteBuffer(camera_, CL_FALSE, 0, sizeof(camera), &camera);
  q.enqueueWriteBuffer(pose_, CL_FALSE, 0, 12 * sizeof(float), T_C_W);
  q.enqueueWriteBuffer(changed_, CL_FALSE, 0, n * sizeof(int), changed_host_.data());
  kernel_.setArg(0, voxels_);
  kernel_.setArg(1, greys_);
  kernel_.setArg(2, coords_);
  kernel_.setArg(3, depth_);
  kernel_.setArg(4, image_);
  kernel_.setArg(5, static_cast<cl_int>(has_image ? 1 : 0));
  kernel_.setArg(6, camera_);
  kernel_.setArg(7, pose_);
  kernel_.setArg(8, voxel_size_);
  kernel_.setArg(9, mu_);
  kernel_.setArg(10, max_weight_);
  kernel_.setArg(11, obs_weight);
  kernel_.setArg(12, changed_);
  q.enqueueNDRangeKernel(kernel_, cl::NullRange, cl::NDRange(n * FM_BLOCK_VOXELS), cl::NDRange(64));
  q.enqueueReadBuffer(voxels_, CL_FALSE, 0, voxel_bytes, staging_.data());
  q.enqueueReadBuffer(greys_, CL_FALSE, 0, grey_bytes, grey_staging_.data());
  q.enqueueReadBuffer(changed_, CL_TRUE, 0, n * sizeof(int), changed_host_.data());
  for (size_t b = 0; b < n; ++b) {
    std::memcpy(blocks[b].second->voxels.data(), &staging_[b * FM_BLOCK_VOXELS], sizeof(VoxelBlock::voxels));
    std::memcpy(blocks[b].second->grey.data(), &grey_staging_[b * FM_BLOCK_VOXELS], sizeof(VoxelBlock::grey));
    (*changed)[b] = static_cast<char>(changed_host_[b] != 0);
  }
}

}  // namespace fisheye_mapping
