#include "fisheye_mapping/ros/stage_messages.h"

#include <algorithm>
#include <cstdio>

#include <diagnostic_msgs/DiagnosticStatus.h>

#include "fisheye_mapping/core/detection/mask_decisions.h"
#include "fisheye_mapping/ros/camera_info.h"
#include "fisheye_mapping/ros/conversions.h"

namespace fisheye_mapping {

RigSelfCalibration toRigSelfCalibrationMsg(const OnlineRigCalibrator& cal, const std::string& reference_camera,
                                           const std_msgs::Header& header) {
  RigSelfCalibration msg;
  msg.header = header;
  msg.reference_camera = reference_camera;
  msg.frame_sets = cal.frameSets();
  msg.updates = cal.updates();
  msg.last_update_ms = cal.lastUpdateMs();
  msg.note = cal.lastNote();
  msg.start_error = cal.startError();
  for (const CameraCalibrationState& c : cal.state()) {
    CameraSelfCalibration m;
    m.camera = c.name;
    m.reference = c.reference;
    m.level = c.warn ? diagnostic_msgs::DiagnosticStatus::WARN : diagnostic_msgs::DiagnosticStatus::OK;
    m.status = c.status;
    for (int a = 0; a < 3; ++a) m.correction_rotvec_deg[a] = c.correction_rotvec_deg[a];
    m.correction_deg = c.correction_deg;
    m.residual_deg = c.residual_deg;
    m.inliers = c.inliers;
    m.updates = c.updates;
    m.refused = c.refused;
    m.restarts = c.restarts;
    for (int a = 0; a < 3; ++a) m.translation_correction_mm[a] = c.translation_correction_mm[a];
    m.translation_updates = c.translation_updates;
    m.metric_matches = c.metric_matches;
    m.translation_status = c.translation_status;
    msg.cameras.push_back(m);
  }
  return msg;
}

void addSelfCalibrationReport(diagnostic_updater::DiagnosticStatusWrapper& stat, const RigSelfCalibration& state,
                              bool enabled) {
  if (state.cameras.empty()) {
    stat.add("self-calibration", enabled ? "on, no rig yet" : "off");
    return;
  }
  char last[32];
  std::snprintf(last, sizeof(last), "%.0f ms", state.last_update_ms);
  stat.add("self-calibration", std::to_string(state.updates) + " updates over " + std::to_string(state.frame_sets) +
                                   " frame sets, last " + last + (state.note.empty() ? "" : "; " + state.note));
  if (!state.start_error.empty()) stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, state.start_error);
  for (const CameraSelfCalibration& c : state.cameras) {
    if (c.reference) continue;
    char line[160];
    std::snprintf(line, sizeof(line), "correction %.3f deg, residual %.3f deg, %d inliers, %d updates: ",
                  c.correction_deg, c.residual_deg, c.inliers, c.updates);
    stat.add("self-calibration " + c.camera, line + c.status);
    char tline[160];
    std::snprintf(tline, sizeof(tline), "correction [%.1f %.1f %.1f] mm, %d metric matches, %d updates: ",
                  c.translation_correction_mm[0], c.translation_correction_mm[1], c.translation_correction_mm[2],
                  c.metric_matches, c.translation_updates);
    stat.add("self-calibration " + c.camera + " translation", tline + c.translation_status);
    if (c.level != diagnostic_msgs::DiagnosticStatus::OK)
      stat.mergeSummary(c.level, "self-calibration " + c.camera + ": " + c.status);
  }
}

std::vector<cv::Mat> depthStageImages(const CameraFrameSetConstPtr& set, const DepthStage& stage,
                                      sensor_msgs::ImageConstPtr* reference) {
  if (set->camera_names.size() != set->images.size()) {
    throw std::invalid_argument("frame set has " + std::to_string(set->camera_names.size()) + " names but " +
                                std::to_string(set->images.size()) + " images");
  }
  const Rig& rig = stage.rig();
  std::vector<cv::Mat> images(rig.cameras.size());
  std::vector<int> wanted = stage.supports();
  wanted.insert(wanted.begin(), stage.reference());
  reference->reset();
  for (int cam : wanted) {
    const auto it = std::find(set->camera_names.begin(), set->camera_names.end(), rig.cameras[cam].name);
    if (it == set->camera_names.end()) continue;
    const sensor_msgs::ImageConstPtr img(set, &set->images[std::size_t(it - set->camera_names.begin())]);
    images[cam] = toCvImageShare(img, ImageTarget::kSweep, rig.cameras[cam].name);
    if (cam == stage.reference()) *reference = img;
  }
  if (!*reference)
    throw std::invalid_argument("frame set has no image of the reference camera " + rig.cameras[stage.reference()].name);
  return images;
}

std::string saveSelfCalibration(const DepthStage& stage, const std::string& requested, const SaveFolder& folder) {
  if (requested.empty()) throw std::invalid_argument("no path given and ~self_calibration_file is empty");
  // Inside ~save_directory (confineSavePath creates missing folders).
  const std::string path = confineSavePath(requested, folder);
  stage.saveCalibration(path);
  return "self-calibrated camchain saved to " + path + " (mount: " + OnlineRigCalibrator::savedMountPath(path) + ")";
}

bool CameraInfoRigKey::describes(const std::vector<std::string>& other_names,
                                 const std::vector<sensor_msgs::CameraInfo>& other_infos) const {
  return other_names == names && other_infos.size() == infos.size() &&
         std::equal(infos.begin(), infos.end(), other_infos.begin(), sameCalibration);
}

TrackedVehicleArray toTrackedVehicleArrayMsg(const std_msgs::Header& header, const std::string& world_frame,
                                             int image_w, int image_h, const Detection2DArray& dets,
                                             const std::vector<VehicleMotionTracker::Decision>& decisions,
                                             bool mask_parked, const std::vector<Eigen::AlignedBox3d>& ghosts) {
  TrackedVehicleArray out;
  out.header = header;
  out.world_frame = world_frame;
  out.image_width = uint32_t(image_w);
  out.image_height = uint32_t(image_h);
  for (std::size_t i = 0; i < dets.detections.size() && i < decisions.size(); ++i) {
    TrackedVehicle v;
    v.detection = dets.detections[i];
    const auto& d = decisions[i];
    v.motion = d.motion == VehicleMotion::Moving   ? TrackedVehicle::MOVING
               : d.motion == VehicleMotion::Parked ? TrackedVehicle::PARKED
                                                   : TrackedVehicle::UNDECIDED;
    v.masked = masksVehicle(d.motion, mask_parked);
    v.track_id = d.track;
    v.speed = float(d.speed);
    v.position.x = d.position.x();
    v.position.y = d.position.y();
    v.position.z = d.position.z();
    out.vehicles.push_back(v);
  }
  for (const Eigen::AlignedBox3d& g : ghosts) {
    geometry_msgs::Point lo, hi;
    lo.x = g.min().x(), lo.y = g.min().y(), lo.z = g.min().z();
    hi.x = g.max().x(), hi.y = g.max().y(), hi.z = g.max().z();
    out.carve_min.push_back(lo);
    out.carve_max.push_back(hi);
  }
  return out;
}

}  // namespace fisheye_mapping
