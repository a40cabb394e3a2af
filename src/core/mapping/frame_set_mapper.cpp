#include "fisheye_mapping/core/mapping/frame_set_mapper.h"

#include <chrono>
#include <stdexcept>
#include <utility>

namespace fisheye_mapping {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

}  // namespace

void FrameSetMapperConfig::validate() const {
  depth.validate();
  detection.validate();
  mask.validate();
  tsdf.validate();
  if (mesh_every < 1) throw std::invalid_argument("mesh_every must be at least 1, got " + std::to_string(mesh_every));
}

FrameSetMapperConfig FrameSetMapperConfig::fromParams(const ParamSource& depth, const ParamSource& detection,
                                                      const ParamSource& mask, const ParamSource& tsdf) {
  FrameSetMapperConfig c;
  c.depth = DepthStageConfig::fromParams(depth);
  c.detection = DetectorStageConfig::fromParams(detection);
  c.mask = DepthMaskConfig::fromParams(mask);
  c.tsdf = TsdfConfig::fromParams(tsdf);
  c.validate();
  return c;
}

FrameSetMapper::FrameSetMapper(const Rig& rig, const FrameSetMapperConfig& config, std::unique_ptr<Detector> detector)
    : config_(config),
      depth_(rig, config.depth),
      detector_(std::move(detector)),
      map_(std::make_unique<TsdfMap>(config.tsdf)),
      mesher_(config.tsdf.min_observations) {
  config_.validate();
}

FrameSetResult FrameSetMapper::process(const std::vector<cv::Mat>& images, const Eigen::Isometry3d& T_W_B,
                                       const std::optional<ImageBoxes>& boxes) {
  const auto t0 = Clock::now();
  FrameSetResult r;
  r.depth = depth_.compute(images);
  r.ms.depth_ms = msSince(t0);
  r = maskAndFuse(std::move(r), images[depth_.reference()], T_W_B, boxes);
  r.ms.total_ms = msSince(t0);
  return r;
}

FrameSetResult FrameSetMapper::processDepth(cv::Mat depth, const Eigen::Isometry3d& T_W_B,
                                            const std::optional<ImageBoxes>& boxes) {
  if (detector_) throw std::invalid_argument("a given depth map has no image for the detector; give boxes instead");
  const auto t0 = Clock::now();
  FrameSetResult r;
  r.depth.depth = std::move(depth);
  r.ms.depth_ms = msSince(t0);
  r = maskAndFuse(std::move(r), cv::Mat(), T_W_B, boxes);
  r.ms.total_ms = msSince(t0);
  return r;
}

FrameSetResult FrameSetMapper::maskAndFuse(FrameSetResult r, const cv::Mat& reference_image,
                                           const Eigen::Isometry3d& T_W_B, const std::optional<ImageBoxes>& boxes) {
  const auto td = Clock::now();
  ImageBoxes found;
  const ImageBoxes* use = boxes ? &*boxes : nullptr;
  if (detector_) {
    found.boxes = detector_->detect(reference_image, config_.detection.only_moving);
    found.image_width = reference_image.cols;
    found.image_height = reference_image.rows;
    use = &found;
  }
  r.ms.detect_ms = msSince(td);
  const auto tm = Clock::now();
  cv::Mat& depth = r.depth.depth;
  const int bw = use && use->image_width > 0 ? use->image_width : depth.cols;
  const int bh = use && use->image_height > 0 ? use->image_height : depth.rows;
  r.mask = maskDepthBoxes(depth, use ? use->boxes : std::vector<Detection>{}, float(config_.mask.margin_px), bw, bh);
  r.masked_pixels = size_t(cv::countNonZero(r.mask));
  r.ms.mask_ms = msSince(tm);
  const auto tf = Clock::now();
  const RigCamera& ref = depth_.rig().cameras[depth_.reference()];
  r.fusion = map_->integrate(depth, ref.model, T_W_B * ref.T_base_cam, T_W_B.translation());
  if (++frame_sets_ % size_t(config_.mesh_every) == 0) mesher_.update(*map_);
  r.ms.fuse_ms = msSince(tf);
  return r;
}

void FrameSetMapper::finish() { mesher_.update(*map_); }

}  // namespace fisheye_mapping
