#include "fisheye_mapping/core/sync/sync_report.h"

#include <algorithm>

namespace fisheye_mapping {

std::vector<std::string> imageTopicsForRig(const Rig& rig, std::vector<std::string> topics) {
  if (topics.empty()) {
    for (const auto& c : rig.cameras) {
      if (c.rostopic.empty()) throw CalibrationError("camera " + c.name + " has no rostopic in the camchain; set ~image_topics");
      topics.push_back(c.rostopic);
    }
  }
  if (topics.size() != rig.cameras.size())
    throw CalibrationError("~image_topics has " + std::to_string(topics.size()) + " topics for " +
                           std::to_string(rig.cameras.size()) + " cameras");
  return topics;
}

std::optional<std::string> imageSizeMismatch(int width, int height, const std::string& encoding,
                                             const CameraModel& camera) {
  if (width == camera.width() && height == camera.height()) return std::nullopt;
  return "image " + std::to_string(width) + "x" + std::to_string(height) + " " + encoding +
         ": the calibration says " + std::to_string(camera.width()) + "x" + std::to_string(camera.height());
}

CameraActivity::CameraActivity(int cameras, double window_s) : cams_(std::size_t(std::max(0, cameras))) {
  for (auto& c : cams_) c.stats = std::make_unique<StageStats>(window_s);
}

void CameraActivity::arrived(int cam, double now_s) {
  Camera& c = cams_.at(std::size_t(cam));
  ++c.received;
  c.last_arrival = now_s;
  c.stats->input();
}

void CameraActivity::clockWentBack(double now_s) {
  for (auto& c : cams_) {
    if (c.received) c.last_arrival = now_s;
  }
  started_ = now_s;
}

std::vector<int> CameraActivity::silent(double now_s, double silent_s) {
  if (started_ == 0) started_ = now_s;
  std::vector<int> out;
  for (std::size_t i = 0; i < cams_.size(); ++i) {
    const double since = cams_[i].received ? cams_[i].last_arrival : started_;
    if (since != 0 && now_s - since > silent_s) out.push_back(int(i));
  }
  return out;
}

}  // namespace fisheye_mapping
