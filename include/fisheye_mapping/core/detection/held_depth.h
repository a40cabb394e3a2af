// The depth of vehicles not decided yet, held back and fused once they are
// decided parked (issue 31). No ROS.
//
// A vehicle is masked out of the depth until VehicleMotionTracker decides
// it, so that nothing that moves leaves a trail; most parked cars are
// decided within a second, and the frame sets before that would be lost to
// the map. VehicleDepthHold keeps, for each tracked vehicle that is still
// undecided, the depth its box masked (the box grown by the mask's margin,
// less the pixels any other masked box covers) for `hold_time` seconds. When
// the vehicle is decided parked, that depth of each earlier frame set is
// handed out, to be fused with that frame set's pose
// (TsdfFusionStage::fuseHeld); when it is decided moving, or its depth is
// older than hold_time, it is dropped. A vehicle is held only until its
// first decision: a parked vehicle's box masked later (placed away from
// where it stands: another vehicle taken for it, or it drives off) is not.
#ifndef FISHEYE_MAPPING_CORE_DETECTION_HELD_DEPTH_H_
#define FISHEYE_MAPPING_CORE_DETECTION_HELD_DEPTH_H_

#include <cstdint>
#include <deque>
#include <map>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "fisheye_mapping/core/detection/detector.h"
#include "fisheye_mapping/core/detection/vehicle_motion.h"

namespace fisheye_mapping {

class VehicleDepthHold {
 public:
  /// The held depth of one earlier frame set: CV_32FC1 of the depth's size,
  /// NaN except the released vehicles' pixels.
  struct Frame {
    std::int64_t stamp_ns = 0;
    cv::Mat depth;
  };

  /// hold_time: seconds a frame set's depth is held (0: nothing is held).
  /// Throws std::invalid_argument on a negative or non-finite hold_time.
  explicit VehicleDepthHold(double hold_time_s);

  /// One frame set: `depth` before masking (CV_32FC1), its boxes (of an
  /// image_w x image_h image) and their decisions (boxes[i] by decisions[i]),
  /// the mask's margin. Returns the held depth of the earlier frame sets of
  /// every vehicle decided parked in this one, oldest first (none when none).
  /// A stamp before the last one drops everything held. Throws
  /// std::invalid_argument on a depth that is not CV_32FC1, a non-positive
  /// image size, or decisions not one per box.
  std::vector<Frame> update(std::int64_t stamp_ns, const cv::Mat& depth, const std::vector<Detection>& boxes,
                            const std::vector<VehicleMotionTracker::Decision>& decisions, float margin_px,
                            int image_w, int image_h);
  void reset();
  double holdTime() const { return hold_time_; }
  /// Pixels held now, over every frame set and vehicle.
  std::size_t heldPixels() const;
  /// Frame sets released and pixels handed out since the start.
  std::size_t releasedFrames() const { return released_frames_; }
  std::size_t releasedPixels() const { return released_pixels_; }

 private:
  struct Held {
    std::int64_t stamp_ns = 0;
    cv::Size size;
    // Per track: (pixel index, range) of what its box alone masked.
    std::map<int, std::vector<std::pair<int, float>>> tracks;
  };
  double hold_time_;
  std::deque<Held> frames_;
  // Tracks decided once (never held again), with the stamp they were last
  // seen (forgotten hold_time after).
  std::map<int, std::int64_t> decided_;
  std::int64_t last_stamp_ns_ = 0;
  bool any_ = false;
  std::size_t released_frames_ = 0, released_pixels_ = 0;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_DETECTION_HELD_DEPTH_H_
