#include "fisheye_mapping/core/depth/depth_stage.h"

#include <stdexcept>
#include <utility>

#include <opencv2/imgcodecs.hpp>

#include "fisheye_mapping/core/common/param_table.h"
#include "fisheye_mapping/core/common/safe_open.h"

namespace fisheye_mapping {

const ParamTable<DepthStageConfig>& DepthStageConfig::params() {
  using C = DepthStageConfig;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("depth");
    t.text("reference_camera", [](C& c) -> std::string& { return c.reference_camera; },
           "Camera whose depth is computed")
        .names("support_cameras", [](C& c) -> std::vector<std::string>& { return c.support_cameras; },
               "Supporting cameras by name; empty: every other camera of the rig")
        .table("self_masks", [](C& c) -> std::map<std::string, std::string>& { return c.self_masks; },
               "Camera name -> 8-bit mask image (0 where the camera sees the car itself: never matched)")
        .include(PlaneSweepConfig::params(), [](C& c) -> PlaneSweepConfig& { return c.sweep; })
        .include(SelfCalibrationConfig::params(), [](C& c) -> SelfCalibrationConfig& { return c.self_calibration; });
    t.rule([](const C& c) {
      if (c.reference_camera.empty()) throw std::invalid_argument("reference_camera: empty camera name");
      for (const auto& n : c.support_cameras) {
        if (n.empty()) throw std::invalid_argument("support_cameras: empty camera name");
        if (n == c.reference_camera)
          throw std::invalid_argument("support_cameras: '" + n + "' is the reference camera");
      }
      for (const auto& [name, path] : c.self_masks)
        if (path.empty()) throw std::invalid_argument("self_masks: empty path for camera '" + name + "'");
    });
    return t;
  }();
  return t;
}

void DepthStageConfig::validate() const { params().check(*this); }

DepthStageConfig DepthStageConfig::fromParams(const ParamSource& p) { return params().read(p, DepthStageConfig()); }

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
    try {
      masks_[i] = readImageFile(path, cv::IMREAD_GRAYSCALE, "self mask of " + name);
    } catch (const std::runtime_error& e) {
      throw CalibrationError("~self_masks: cannot read " + path + ": " + e.what());
    }
  }
  sweep_ = std::make_unique<PlaneSweep>(config.sweep);
  if (config.self_calibration.enabled && !supports_.empty()) {
    // The calibrator's masks mark the car body (non-zero), the stage's the scene.
    std::vector<cv::Mat> body(masks_.size());
    for (size_t i = 0; i < masks_.size(); ++i)
      if (!masks_[i].empty()) body[i] = masks_[i] == 0;
    try {
      calibration_ = std::make_unique<OnlineRigCalibrator>(rig_, ref_, supports_, body, config.self_calibration);
    } catch (const std::invalid_argument& e) {
      throw CalibrationError(std::string("self-calibration: ") + e.what());
    }
    rig_ = calibration_->rig();  // corrected from the start when started from a saved calibration
  }
}

void DepthStage::saveCalibration(const std::string& camchain_path) const {
  if (!calibration_) throw std::runtime_error("self-calibration is off (~self_calibration false): nothing to save");
  calibration_->saveCalibration(camchain_path);
}

void DepthStage::setSweepConfig(const PlaneSweepConfig& config) {
  config.validate();
  sweep_ = std::make_unique<PlaneSweep>(config);
}

DepthResult DepthStage::compute(const std::vector<cv::Mat>& images, const Eigen::Isometry3d* T_world_base) {
  if (images.size() != rig_.cameras.size())
    throw std::invalid_argument("frame set has " + std::to_string(images.size()) + " images for a rig of " +
                                std::to_string(rig_.cameras.size()) + " cameras");
  if (images[ref_].empty())
    throw std::invalid_argument("frame set has no image of the reference camera " + rig_.cameras[ref_].name);
  double calibration_ms = 0.0;
  if (calibration_) {
    if (calibration_->observe(images, T_world_base)) rig_ = calibration_->rig();
    calibration_ms = calibration_->lastCallMs();
  }
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
  r.calibration_ms = calibration_ms;
  r.total_ms += calibration_ms;
  return r;
}

}  // namespace fisheye_mapping
