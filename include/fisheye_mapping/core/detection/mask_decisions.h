// The depth mask stage's bookkeeping around maskDepthBoxes and the vehicle
// tracker: which boxes are masked, the decisions counted and drawn, and the
// camera_info that follows the masked depth (republished, latched, even when
// it arrives after the depth). No ROS.
#ifndef FISHEYE_MAPPING_CORE_DETECTION_MASK_DECISIONS_H_
#define FISHEYE_MAPPING_CORE_DETECTION_MASK_DECISIONS_H_

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "fisheye_mapping/core/detection/detector.h"
#include "fisheye_mapping/core/detection/vehicle_motion.h"

namespace fisheye_mapping {

/// Whether a vehicle so decided is masked: moving and undecided ones always,
/// parked ones only with mask_parked.
inline bool masksVehicle(VehicleMotion m, bool mask_parked) { return mask_parked || m != VehicleMotion::Parked; }

/// The boxes to mask (boxes[i] decided by decisions[i]; a box without a
/// decision is masked).
std::vector<Detection> boxesToMask(const std::vector<Detection>& boxes,
                                   const std::vector<VehicleMotionTracker::Decision>& decisions, bool mask_parked);

/// Each box's decision by `tracker` (VehicleMotionTracker::update) and the
/// tracking state for the diagnostics in *state: "tracking in <world>" when
/// tracked with a pose; `why_not` (the missing camera or pose) when there is
/// no camera or no pose; "not tracked: <error>: every vehicle masked" when the
/// tracker throws. Without a camera, or after a throw, every box is
/// undecided. No boxes: none, and *state is left as it was.
std::vector<VehicleMotionTracker::Decision> decideVehicles(VehicleMotionTracker& tracker,
                                                           const std::vector<Detection>& boxes, int image_w,
                                                           int image_h, const cv::Mat& depth,
                                                           const CameraModel* camera,
                                                           const std::optional<Eigen::Isometry3d>& T_W_C,
                                                           double stamp_s, const std::string& world,
                                                           const std::string& why_not, std::string* state);

/// Decisions counted by kind since the start; text(): "moving / parked / undecided".
struct MotionCounts {
  std::uint64_t moving = 0, parked = 0, undecided = 0;
  void add(const std::vector<VehicleMotionTracker::Decision>& decisions);
  std::string text() const;
};

/// Draws each box of an image_w x image_h image on `colour` (BGR8, of any
/// size: the boxes are scaled to it) in its decision's colour - red (0, 0, 255)
/// moving, green (0, 200, 0) parked, yellow (0, 220, 255) undecided - 2 px
/// wide, labelled with the decision and the speed when measured. Boxes with a
/// non-finite corner are skipped.
void drawVehicleDecisions(cv::Mat* colour, const std::vector<Detection>& boxes,
                          const std::vector<VehicleMotionTracker::Decision>& decisions, int image_w, int image_h);

/// The camera_info next to a stage's output: the latest one received, sent
/// with each output's header when it fits the output's size, never waited
/// for. An output that goes out before any camera_info has come is
/// remembered (the last one, by its header and size): when the first
/// camera_info arrives it is sent for that output at once, so that a consumer
/// waiting for the pair need not wait for the next. `Header`: any copyable
/// type (the ROS side uses std_msgs::Header). Not thread-safe.
template <class Header>
class InfoRelay {
 public:
  enum class Action {
    kSend,      ///< send the camera_info with this output's header
    kWait,      ///< none yet: remembered (first() tells whether it is the first time)
    kMismatch,  ///< of another size: not sent (problem() says why)
  };
  struct Output {
    Header header;
    int width = 0, height = 0;
  };

  explicit InfoRelay(std::string info_topic) : topic_(std::move(info_topic)) {}

  /// An output of width x height went out with `header`.
  Action output(const Header& header, int width, int height) {
    if (!info_) {
      first_wait_ = !told_;
      told_ = true;
      waiting_ = Output{header, width, height};
      return Action::kWait;
    }
    first_wait_ = false;
    if (info_->first != width || info_->second != height) {
      problem_ = "not republished: " + topic_ + " is " + std::to_string(info_->first) + "x" +
                 std::to_string(info_->second) + ", the depth " + std::to_string(width) + "x" + std::to_string(height);
      return Action::kMismatch;
    }
    problem_.clear();
    return Action::kSend;
  }

  /// A camera_info of width x height arrived: the output still waiting for
  /// one, if any (pass it to output() again to decide).
  std::optional<Output> info(int width, int height) {
    info_ = std::make_pair(width, height);
    std::optional<Output> out;
    out.swap(waiting_);
    return out;
  }

  /// Whether the last output() was the first to wait (say so once).
  bool firstWait() const { return first_wait_; }
  const std::string& problem() const { return problem_; }
  /// For the diagnostics: none yet, the problem, or republished.
  std::string state(const std::string& out_topic) const {
    if (!info_) return "none received on " + topic_ + ": " + out_topic + " not published";
    if (!problem_.empty()) return problem_;
    return "republished from " + topic_;
  }

 private:
  std::string topic_;
  std::optional<std::pair<int, int>> info_;  // the latest camera_info's size
  std::optional<Output> waiting_;
  std::string problem_;
  bool told_ = false, first_wait_ = false;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_DETECTION_MASK_DECISIONS_H_
