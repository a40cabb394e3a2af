// The stages' own messages and their diagnostics (library
// fisheye_mapping_ros): the depth stage's self-calibration state
// (RigSelfCalibration) and the rig it keeps for a frame set's CameraInfos,
// the mask stage's tracked vehicles (TrackedVehicleArray).
#ifndef FISHEYE_MAPPING_ROS_STAGE_MESSAGES_H_
#define FISHEYE_MAPPING_ROS_STAGE_MESSAGES_H_

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <diagnostic_updater/DiagnosticStatusWrapper.h>
#include <sensor_msgs/CameraInfo.h>
#include <std_msgs/Header.h>

#include <opencv2/core.hpp>
#include <sensor_msgs/Image.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/RigSelfCalibration.h"
#include "fisheye_mapping/TrackedVehicleArray.h"
#include "fisheye_mapping/core/camera/online_calibration.h"
#include "fisheye_mapping/core/common/safe_write.h"
#include "fisheye_mapping/core/depth/depth_stage.h"
#include "fisheye_mapping/core/detection/vehicle_motion.h"

namespace fisheye_mapping {

/// The self-calibration's state as its topic carries it: the counts, the last
/// note, the start error and each camera's correction (level WARN for a
/// camera that gets no update for a reason the user should see).
RigSelfCalibration toRigSelfCalibrationMsg(const OnlineRigCalibrator& cal, const std::string& reference_camera,
                                           const std_msgs::Header& header);

/// The self-calibration on /diagnostics: "self-calibration" ("<n> updates over
/// <m> frame sets, last <t> ms[; note]", or "on, no rig yet" / "off" before
/// any state) and "self-calibration <camera>" per supporting camera, each
/// camera's level and the start error merged into the summary.
void addSelfCalibrationReport(diagnostic_updater::DiagnosticStatusWrapper& stat, const RigSelfCalibration& state,
                              bool enabled);

/// The images of a frame set for `stage`, in rig order (an empty cv::Mat for
/// a camera not in the set, which DepthStage names), sharing the set's
/// pixels; *reference: the reference camera's image message (aliasing `set`).
/// Throws std::invalid_argument when names and images differ in count or the
/// reference camera's image is missing, ImageConversionError for an image the
/// sweep cannot read.
std::vector<cv::Mat> depthStageImages(const CameraFrameSetConstPtr& set, const DepthStage& stage,
                                      sensor_msgs::ImageConstPtr* reference);

/// Saves the stage's self-calibrated camchain (and its mount beside it) at
/// `requested` inside `folder` (confineSavePath); returns what was written,
/// for the log and the service's reply. Throws with the reason (no
/// self-calibration, a path outside the folder, a failed write).
std::string saveSelfCalibration(const DepthStage& stage, const std::string& requested, const SaveFolder& folder);

/// The CameraInfos (with the cameras' names) a rig was built from.
struct CameraInfoRigKey {
  std::vector<std::string> names;
  std::vector<sensor_msgs::CameraInfo> infos;
  /// Whether a rig built from these describes cameras `names` with `infos`
  /// (sameCalibration: stamps may differ).
  bool describes(const std::vector<std::string>& names, const std::vector<sensor_msgs::CameraInfo>& infos) const;
};

/// depth_masked/vehicles: each detection of `dets` with its decision (the
/// decisions in the message's order; a detection without one is left out),
/// masked or not (masksVehicle), and the regions parked vehicles left
/// (`ghosts`, carve_min / carve_max in the world frame).
TrackedVehicleArray toTrackedVehicleArrayMsg(const std_msgs::Header& header, const std::string& world_frame,
                                             int image_w, int image_h, const Detection2DArray& dets,
                                             const std::vector<VehicleMotionTracker::Decision>& decisions,
                                             bool mask_parked, const std::vector<Eigen::AlignedBox3d>& ghosts);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_STAGE_MESSAGES_H_
