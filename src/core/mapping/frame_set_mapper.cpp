#include "fisheye_mapping/core/mapping/frame_set_mapper.h"

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace fisheye_mapping {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// Offline: no map file, and frame sets come in the order given (no time resets).
TsdfStageOptions offlineTsdfOptions() {
  TsdfStageOptions o;
  o.time_reset_threshold = 0.0;
  return o;
}

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
      tsdf_(std::make_unique<TsdfFusionStage>(config.tsdf, offlineTsdfOptions(), nullptr)),
      motion_(config.mask.motion),
      hold_(config.mask.mask_parked ? 0.0 : config.mask.hold_time) {
  config_.validate();
}

FrameSetResult FrameSetMapper::depthOf(const std::vector<cv::Mat>& images, const Eigen::Isometry3d* T_W_B) {
  const auto t0 = Clock::now();
  FrameSetResult r;
  r.depth = depth_.compute(images, T_W_B);
  r.ms.depth_ms = msSince(t0);
  if (r.depth.calibration_ms > 0 && depth_.selfCalibration()) {
    r.calibration = depth_.selfCalibration()->state();
    r.calibrated_rig = depth_.selfCalibration()->rig();
  }
  return r;
}

FrameSetResult FrameSetMapper::process(const std::vector<cv::Mat>& images, const Eigen::Isometry3d& T_W_B,
                                       const std::optional<ImageBoxes>& boxes, double stamp_s) {
  flush();
  const auto t0 = Clock::now();
  FrameSetResult r = depthOf(images, &T_W_B);
  double detect_ms = 0;
  const ImageBoxes use = boxesFor(images[depth_.reference()], boxes, &detect_ms);
  r = maskAndFuse(std::move(r), use, T_W_B, depth_.rig().cameras[depth_.reference()], stamp_s,
                  images[depth_.reference()]);
  r.ms.detect_ms = detect_ms;
  r.ms.total_ms = msSince(t0);
  return r;
}

FrameSetResult FrameSetMapper::processDepth(cv::Mat depth, const Eigen::Isometry3d& T_W_B,
                                            const std::optional<ImageBoxes>& boxes, const cv::Mat& grey) {
  if (detector_) throw std::invalid_argument("a given depth map has no image for the detector; give boxes instead");
  flush();
  const auto t0 = Clock::now();
  FrameSetResult r;
  r.depth.depth = std::move(depth);
  r.ms.depth_ms = msSince(t0);
  double detect_ms = 0;
  r = maskAndFuse(std::move(r), boxesFor(cv::Mat(), boxes, &detect_ms), T_W_B,
                  depth_.rig().cameras[depth_.reference()], std::numeric_limits<double>::quiet_NaN(), grey);
  r.ms.total_ms = msSince(t0);
  return r;
}

std::optional<FrameSetResult> FrameSetMapper::submit(const std::vector<cv::Mat>& images,
                                                     const Eigen::Isometry3d& T_W_B,
                                                     const std::optional<ImageBoxes>& boxes, double stamp_s) {
  const auto t0 = Clock::now();
  if (images.size() <= static_cast<size_t>(depth_.reference())) {
    depthOf(images);  // the depth stage names what is wrong; nothing is started
    throw std::invalid_argument("a frame set without the reference camera's image");
  }
  // This set's detection, once the previous one is done (one detector, one
  // call at a time): on a copy of the reference image, which the caller may
  // reuse.
  if (detection_.valid()) detection_.wait();
  const cv::Mat reference = images[depth_.reference()].clone();
  auto timed_boxes = std::make_shared<double>(0.0);
  detection_ = std::async(std::launch::async, [this, reference, boxes, timed_boxes] {
                 return boxesFor(reference, boxes, timed_boxes.get());
               }).share();
  FrameSetResult r;
  try {
    r = depthOf(images, &T_W_B);
  } catch (...) {
    detection_.wait();  // the detection of a frame set that is dropped
    throw;
  }
  // The previous set's fusion must end before this one's starts (one map).
  std::optional<FrameSetResult> previous = flush();
  std::shared_future<ImageBoxes> detection = detection_;
  // The reference camera as now (the self-calibration of the next set may
  // change the rig while this one fuses).
  const RigCamera ref = depth_.rig().cameras[depth_.reference()];
  pending_ = std::async(std::launch::async,
                        [this, r = std::move(r), detection, timed_boxes, T_W_B, t0, ref, stamp_s, reference]() mutable {
    const ImageBoxes use = detection.get();
    FrameSetResult out = maskAndFuse(std::move(r), use, T_W_B, ref, stamp_s, reference);
    out.ms.detect_ms = *timed_boxes;
    out.ms.total_ms = msSince(t0);
    return out;
  });
  return previous;
}

std::optional<FrameSetResult> FrameSetMapper::flush() {
  if (!pending_.valid()) return std::nullopt;
  return pending_.get();  // rethrows the frame set's detection or fusion error
}

ImageBoxes FrameSetMapper::boxesFor(const cv::Mat& reference_image, const std::optional<ImageBoxes>& given,
                                    double* ms) {
  const auto td = Clock::now();
  ImageBoxes found;
  if (detector_) {
    found.boxes = detector_->detect(reference_image, config_.detection.only_moving);
    found.image_width = reference_image.cols;
    found.image_height = reference_image.rows;
  } else if (given) {
    found = *given;
  }
  *ms = msSince(td);
  return found;
}

FrameSetResult FrameSetMapper::maskAndFuse(FrameSetResult r, const ImageBoxes& use, const Eigen::Isometry3d& T_W_B,
                                           const RigCamera& ref, double stamp_s, const cv::Mat& image) {
  const auto tm = Clock::now();
  cv::Mat& depth = r.depth.depth;
  const int bw = use.image_width > 0 ? use.image_width : depth.cols;
  const int bh = use.image_height > 0 ? use.image_height : depth.rows;
  r.boxes = use;
  std::vector<Detection> masked = use.boxes;
  const bool tracked =
      detector_ && std::isfinite(stamp_s) && depth.cols == ref.model.width() && depth.rows == ref.model.height();
  if (tracked) {
    // The detector's vehicles, placed by the unmasked depth: parked ones stay.
    r.motion = motion_.update(use.boxes, bw, bh, depth, ref.model, T_W_B * ref.T_base_cam, stamp_s);
    if (!config_.mask.mask_parked) {
      masked.clear();
      for (size_t i = 0; i < use.boxes.size(); ++i) {
        if (r.motion[i].motion != VehicleMotion::Parked) masked.push_back(use.boxes[i]);
      }
    }
  }
  // As the depth mask nodelet: the depth undecided vehicles mask is held, and
  // that of the vehicles decided parked now is fused after this frame set.
  const std::int64_t stamp_ns = std::isfinite(stamp_s) ? std::llround(stamp_s * 1e9) : (next_unstamped_ns_ += 1000000000);
  std::vector<VehicleDepthHold::Frame> released;
  if (tracked && !config_.mask.mask_parked) {
    released = hold_.update(stamp_ns, depth, use.boxes, r.motion, float(config_.mask.margin_px), bw, bh);
  }
  r.mask = maskDepthBoxes(depth, masked, float(config_.mask.margin_px), bw, bh);
  r.masked_pixels = size_t(cv::countNonZero(r.mask));
  r.ms.mask_ms = msSince(tm);
  const auto tf = Clock::now();
  // As the TSDF nodelet: the grey image (the map's intensity, when it is one
  // grey image) and carve regions (parked vehicles that drove off) of the
  // frame set's stamp go to the stage before its depth.
  if (image.type() == CV_8UC1) tsdf_->addGrey(stamp_ns, image);
  tsdf_->setCarve(tracked ? motion_.ghostRegions() : std::vector<Eigen::AlignedBox3d>(), stamp_ns);
  r.fusion = tsdf_->fuse(depth, ref.model, T_W_B * ref.T_base_cam, T_W_B, stamp_ns).stats;
  for (const auto& f : released) {
    if (tsdf_->fuseHeld(f.depth, ref.model, f.stamp_ns)) ++r.held_frames_fused;
  }
  if (++frame_sets_ % size_t(config_.mesh_every) == 0) tsdf_->updateMesh();
  r.ms.fuse_ms = msSince(tf);
  return r;
}

void FrameSetMapper::finish() {
  if (pending_.valid()) pending_.wait();  // its result stays for flush()
  tsdf_->updateMesh();
}

}  // namespace fisheye_mapping
