#include "fisheye_mapping/core/depth/depth_stage.h"

#include <stdexcept>
#include <utility>

#include <opencv2/imgcodecs.hpp>

namespace fisheye_mapping {

void DepthStageConfig::validate() const {
  if (reference_camera.empty()) throw std::invalid_argument("reference_camera: empty camera name");
  for (const auto& n : support_cameras) {
    if (n.empty()) throw std::invalid_argument("support_cameras: empty camera name");
    if (n == reference_camera)
      throw std::invalid_argument("support_cameras: '" + n + "' is the reference camera");
  }
  for (const auto& [name, path] : self_masks) {
    if (path.empty()) throw std::invalid_argument("self_masks: empty path for camera '" + name + "'");
  }
  sweep.validate();
}

DepthStageConfig DepthStageConfig::fromParams(const ParamSource& p) {
  DepthStageConfig c;
  p.get("reference_camera", c.reference_camera);
  p.get("support_cameras", c.support_cameras);
  p.get("self_masks", c.self_masks);
  c.sweep = PlaneSweepConfig::fromParams(p);
  c.validate();
  return c;
}

DepthStage::DepthStage(Rig rig, const DepthStageConfig& config) : rig_(std::move(rig)) {
  config.validate();
  ref_ = rig_.indexOf(config.reference_camera);
  if (ref_ < 0) throw CalibrationError("~reference_camera: no camera '" + config.reference_camera + "' in the rig");
  if (config.support_cameras.empty()) {
    for (int i = 0; i < int(rig_.cameras.size()); ++i)
      if (i != ref_) supports_.push_back(i);
  } else {
    for (const auto& n : config.support_cameras) {
      const int i = rig_.indexOf(n);
      if (i < 0 || i == ref_) throw CalibrationError("~support_cameras: '" + n + "' is not a supporting camera of the rig");
      supports_.push_back(i);
    }
  }
  masks_.resize(rig_.cameras.size());
  for (const auto& [name, path] : config.self_masks) {
    const int i = rig_.indexOf(name);
    if (i < 0) throw CalibrationError("~self_masks: no camera '" + name + "' in the rig");
    masks_[i] = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (masks_[i].empty()) throw CalibrationError("~self_masks: cannot read " + path);
  }
  sweep_ = std::make_unique<PlaneSweep>(config.sweep);
}

void DepthStage::setSweepConfig(const PlaneSweepConfig& config) {
  config.validate();
  sweep_ = std::make_unique<PlaneSweep>(config);
}

DepthResult DepthStage::compute(const std::vector<cv::Mat>& images) {
  if (images.size() != rig_.cameras.size())
    throw std::invalid_argument("frame set has " + std::to_string(images.size()) + " images for a rig of " +
                                std::to_string(rig_.cameras.size()) + " cameras");
  if (images[ref_].empty())
    throw std::invalid_argument("frame set has no image of the reference camera " + rig_.cameras[ref_].name);
  const SweepView ref = rigSweepView(rig_, ref_, ref_, images[ref_], masks_[ref_]);
  std::vector<SweepView> views;
  std::vector<std::string> missing;
  for (int i : supports_) {
    if (images[i].empty()) {
      missing.push_back(rig_.cameras[i].name + ": no image in the frame set; swept without it");
      continue;
    }
    views.push_back(rigSweepView(rig_, i, ref_, images[i], masks_[i]));
  }
  const Eigen::Isometry3d T_base_ref = rig_.cameras[ref_].T_base_cam;
  DepthResult r = sweep_->compute(ref, views, &T_base_ref);
  r.warnings.insert(r.warnings.end(), missing.begin(), missing.end());
  return r;
}

}  // namespace fisheye_mapping
