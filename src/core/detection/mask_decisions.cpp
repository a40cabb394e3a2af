#include "fisheye_mapping/core/detection/mask_decisions.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

namespace fisheye_mapping {

std::vector<Detection> boxesToMask(const std::vector<Detection>& boxes,
                                   const std::vector<VehicleMotionTracker::Decision>& decisions, bool mask_parked) {
  std::vector<Detection> out;
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    if (i >= decisions.size() || masksVehicle(decisions[i].motion, mask_parked)) out.push_back(boxes[i]);
  }
  return out;
}

std::vector<VehicleMotionTracker::Decision> decideVehicles(VehicleMotionTracker& tracker,
                                                           const std::vector<Detection>& boxes, int image_w,
                                                           int image_h, const cv::Mat& depth,
                                                           const CameraModel* camera,
                                                           const std::optional<Eigen::Isometry3d>& T_W_C,
                                                           double stamp_s, const std::string& world,
                                                           const std::string& why_not, std::string* state) {
  std::vector<VehicleMotionTracker::Decision> none(boxes.size());
  if (boxes.empty()) return none;
  if (!camera) {
    *state = why_not;
    return none;
  }
  try {
    auto out = tracker.update(boxes, image_w, image_h, depth, *camera, T_W_C, stamp_s);
    *state = T_W_C ? "tracking in " + world : why_not;
    return out;
  } catch (const std::exception& e) {
    *state = std::string("not tracked: ") + e.what() + ": every vehicle masked";
    return none;
  }
}

void MotionCounts::add(const std::vector<VehicleMotionTracker::Decision>& decisions) {
  for (const auto& d : decisions) {
    moving += d.motion == VehicleMotion::Moving;
    parked += d.motion == VehicleMotion::Parked;
    undecided += d.motion == VehicleMotion::Undecided;
  }
}

std::string MotionCounts::text() const {
  return std::to_string(moving) + " / " + std::to_string(parked) + " / " + std::to_string(undecided);
}

void drawVehicleDecisions(cv::Mat* colour, const std::vector<Detection>& boxes,
                          const std::vector<VehicleMotionTracker::Decision>& decisions, int image_w, int image_h) {
  const double sx = double(colour->cols) / image_w, sy = double(colour->rows) / image_h;
  for (std::size_t i = 0; i < boxes.size() && i < decisions.size(); ++i) {
    const Detection& b = boxes[i];
    if (!std::isfinite(b.x_min) || !std::isfinite(b.y_min) || !std::isfinite(b.x_max) || !std::isfinite(b.y_max))
      continue;
    const VehicleMotion m = decisions[i].motion;
    const cv::Scalar c = m == VehicleMotion::Moving   ? cv::Scalar(0, 0, 255)
                         : m == VehicleMotion::Parked ? cv::Scalar(0, 200, 0)
                                                      : cv::Scalar(0, 220, 255);
    const cv::Point p0(int(b.x_min * sx), int(b.y_min * sy)), p1(int(b.x_max * sx), int(b.y_max * sy));
    cv::rectangle(*colour, p0, p1, c, 2);
    std::string label = toString(m);
    if (std::isfinite(decisions[i].speed)) label += cv::format(" %.1f m/s", decisions[i].speed);
    cv::putText(*colour, label, cv::Point(p0.x, std::max(12, p0.y - 4)), cv::FONT_HERSHEY_SIMPLEX, 0.45, c, 1);
  }
}

}  // namespace fisheye_mapping
