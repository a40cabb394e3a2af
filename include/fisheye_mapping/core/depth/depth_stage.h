// The depth stage of the pipeline (paper Sec. III-A): the rig, the reference
// camera and its supporting views, the self-masks (the car's own body in each
// camera) and the plane sweep, as one object that the depth nodelet and the
// offline FrameSetMapper both call. No ROS.
#ifndef FISHEYE_MAPPING_CORE_DEPTH_DEPTH_STAGE_H_
#define FISHEYE_MAPPING_CORE_DEPTH_DEPTH_STAGE_H_

#include <map>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/online_calibration.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/common/params.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"

namespace fisheye_mapping {

struct DepthStageConfig {
  std::string reference_camera = "cam0";
  // Supporting cameras by name; empty: every camera of the rig but the reference.
  std::vector<std::string> support_cameras;
  // Camera name -> path of an 8-bit mask image (0 where the camera sees the
  // car itself; those pixels are never matched).
  std::map<std::string, std::string> self_masks;
  PlaneSweepConfig sweep;
  // Online rotation self-calibration of the supporting cameras (on by default).
  SelfCalibrationConfig self_calibration;
  // Throws std::invalid_argument naming the parameter.
  void validate() const;
  // The declaration of every parameter, the sweep's included (docs/parameters.md).
  static const ParamTable<DepthStageConfig>& params();
  // The defaults above overlaid with the parameters reference_camera,
  // support_cameras, self_masks and the plane sweep's (PlaneSweepConfig::fromParams);
  // validated.
  static DepthStageConfig fromParams(const ParamSource& p);
};

class DepthStage {
 public:
  // Resolves the camera names against the rig and reads the self-masks.
  // Throws CalibrationError naming the parameter (~reference_camera,
  // ~support_cameras, ~self_masks) when a camera is not in the rig or a mask
  // cannot be read.
  DepthStage(Rig rig, const DepthStageConfig& config);

  // Depth (range along the reference camera's rays, metres, NaN invalid) for
  // one frame set. With self-calibration on, the set first goes to the online
  // calibrator (every self_calibration_period-th set it updates the supporting
  // cameras' rotations, which this and later sets are swept with; its time is
  // DepthResult::calibration_ms, part of total_ms). images: images[i] is the image of rig camera i (grey or BGR, 8/16
  // bit or float); a missing supporting image (empty Mat) is left out and
  // named in DepthResult::warnings; a missing reference image throws
  // std::invalid_argument. T_world_base: the vehicle's pose at the set when
  // known (the self-calibration then also corrects the translations, from
  // the motion between sets). Not thread-safe (one call at a time).
  DepthResult compute(const std::vector<cv::Mat>& images, const Eigen::Isometry3d* T_world_base = nullptr);

  // Changes the filters of the sweep (dynamic reconfiguration); validated.
  void setFilters(const DepthFilterConfig& filters) { sweep_->setFilters(filters); }
  // Replaces the sweep with one of `config` (dynamic reconfiguration of its
  // planes, views or matching: the planes and the backend are built anew; the
  // rig, views and masks stay). Throws std::invalid_argument naming the field,
  // and then keeps the running sweep.
  void setSweepConfig(const PlaneSweepConfig& config);

  // The rig the sweep uses: the given one with the self-calibration's corrections.
  const Rig& rig() const { return rig_; }
  // The online self-calibration, or null when it is off.
  const OnlineRigCalibrator* selfCalibration() const { return calibration_.get(); }
  // Writes the self-calibrated rig (OnlineRigCalibrator::saveCalibration);
  // throws std::runtime_error when self-calibration is off or writing fails.
  void saveCalibration(const std::string& camchain_path) const;
  int reference() const { return ref_; }
  const std::vector<int>& supports() const { return supports_; }
  const PlaneSweepConfig& sweepConfig() const { return sweep_->config(); }
  std::string backendName() const { return sweep_->backendName(); }

 private:
  Rig rig_;
  int ref_ = 0;
  std::vector<int> supports_;
  std::vector<cv::Mat> masks_;  // per rig camera; empty: none
  std::unique_ptr<PlaneSweep> sweep_;
  std::unique_ptr<OnlineRigCalibrator> calibration_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_DEPTH_DEPTH_STAGE_H_
