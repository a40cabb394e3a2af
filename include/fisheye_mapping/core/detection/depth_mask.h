// Removing potentially moving objects from depth maps (paper Sec. III-B), and
// pairing depth maps with the detections of the same image by stamp. No ROS.
#ifndef FISHEYE_MAPPING_CORE_DETECTION_DEPTH_MASK_H_
#define FISHEYE_MAPPING_CORE_DETECTION_DEPTH_MASK_H_

#include "fisheye_mapping/core/detection/detector.h"
#include "fisheye_mapping/core/detection/vehicle_motion.h"

#include <opencv2/core.hpp>

#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <vector>

namespace fisheye_mapping {

class ParamSource;

template <class Config>
class ParamTable;  // fisheye_mapping/core/common/param_table.h

/// The depth mask stage's parameters (the depth mask nodelet's, and the
/// depth_mask section of the offline tools' configuration).
struct DepthMaskConfig {
  double margin_px = 10.0;             ///< boxes grown by this on each side, pixels; >= 0
  double wait_for_detections = 0.5;    ///< s (wall time) a depth map waits for its detections; >= 0
  int max_pending = 30;                ///< depth maps / detection sets held while pairing; >= 1
  double time_reset_threshold = 1.0;   ///< s a stream may step back before the pairing resets; 0: never
  /// Parameter colour_range [near, far]: the colour scale of the colour-coded
  /// masked depth, metres; 0 < near < far.
  double colour_near = 1.0;
  double colour_far = 30.0;
  /// Parked vehicles masked too (every detected vehicle, as before issue 31);
  /// false: only the moving ones and those not decided yet
  /// (VehicleMotionTracker), so that parked cars stay in the map.
  bool mask_parked = false;
  /// s an undecided vehicle's masked depth is held, to be fused once it is
  /// decided parked (VehicleDepthHold); 0: dropped at once, as before
  double hold_time = 3.0;
  VehicleMotionConfig motion;

  /// Throws std::invalid_argument naming the parameter and the bad value.
  void validate() const;
  /// The declaration of every parameter (docs/parameters.md).
  static const ParamTable<DepthMaskConfig>& params();
  /// `base` overlaid with the parameters of the same names in `p`
  /// (colour_range: a list of two numbers); validated. The run-time subset
  /// (margin_px, wait_for_detections, max_pending, time_reset_threshold) is
  /// cfg/DepthMaskReconfigure.cfg's, read through this same function.
  static DepthMaskConfig fromParams(const ParamSource& p, DepthMaskConfig base);
  static DepthMaskConfig fromParams(const ParamSource& p) { return fromParams(p, DepthMaskConfig()); }
};

/// The depth pixels box `b` (of an image_w x image_h image) grown by margin_px
/// on each side covers in a depth map of depth_size, as maskDepthBoxes masks
/// them (a pixel is inside when its centre is); empty when none or when a
/// corner is not finite.
cv::Rect maskedRect(const Detection& b, float margin_px, cv::Size depth_size, int image_w, int image_h);

/// Sets depth to NaN inside every box grown by `margin_px` on each side, and returns
/// the mask (CV_8U, 255 where invalidated by a box). A pixel is inside when its centre
/// is. Boxes refer to an image of `image_w` x `image_h` pixels; they are scaled to the
/// depth map's size when it differs (e.g. half-resolution depth).
/// Throws std::invalid_argument when depth is not CV_32FC1 or the image size is not positive.
cv::Mat maskDepthBoxes(cv::Mat& depth, const std::vector<Detection>& boxes, float margin_px, int image_w,
                       int image_h);

/// Pairs depth maps with detections by exact stamp (nanoseconds). Detections may come
/// before or after their depth; a depth map waits at most `wait_s` for its detections,
/// then is released without them (timed_out). Depth maps leave in the order they came:
/// one whose detections are there waits behind an older one still waiting (released
/// first would put the older one out of order downstream: the fusion stage skips a
/// frame older than the last it fused, and a paced drive lost every other frame set
/// so). `now_s` is any monotonic clock in seconds.
template <class Depth, class Dets>
class StampPairer {
 public:
  struct Pair {
    std::uint64_t stamp;
    Depth depth;
    std::optional<Dets> dets;  ///< empty when released after the wait
    /// Released before its wait ended, because max_pending maps waited.
    bool queue_full = false;
  };
  explicit StampPairer(double wait_s, std::size_t max_pending = 64) : wait_s_(wait_s), max_pending_(max_pending) {}

  void setWait(double wait_s) { wait_s_ = wait_s; }
  /// Takes effect at the next add (the excess is then released / dropped).
  void setMaxPending(std::size_t max_pending) { max_pending_ = max_pending; }

  std::vector<Pair> addDepth(std::uint64_t stamp, Depth depth, double now_s) {
    std::vector<Pair> out;
    std::optional<Dets> dets;
    auto it = dets_.find(stamp);
    if (it != dets_.end()) {
      dets = std::move(it->second);
      dets_.erase(it);
    }
    depth_.push_back({stamp, now_s, std::move(depth), std::move(dets)});
    while (depth_.size() > max_pending_) out.push_back(releaseFront(true));  // never hold more than max_pending
    auto rest = poll(now_s);
    out.insert(out.end(), std::make_move_iterator(rest.begin()), std::make_move_iterator(rest.end()));
    return out;
  }

  std::vector<Pair> addDetections(std::uint64_t stamp, Dets dets, double now_s) {
    for (auto& w : depth_) {
      if (w.stamp != stamp) continue;
      if (!w.dets) w.dets = std::move(dets);
      return poll(now_s);
    }
    if (released_.count(stamp)) {
      ++late_;  // its depth already went out without it
    } else {
      dets_[stamp] = std::move(dets);
      while (dets_.size() > max_pending_) {  // oldest stamp first
        dets_.erase(dets_.begin());
        ++dets_dropped_;
      }
    }
    return poll(now_s);
  }

  /// Releases, oldest first, the depth maps paired with their detections
  /// and those that waited longer than the wait, up to the first that
  /// still waits.
  std::vector<Pair> poll(double now_s) {
    std::vector<Pair> out;
    while (!depth_.empty() && (depth_.front().dets || now_s - depth_.front().arrival >= wait_s_))
      out.push_back(releaseFront(false));
    return out;
  }

  /// Depth maps waiting (for their detections, or behind an older one).
  std::size_t pendingDepth() const { return depth_.size(); }
  std::size_t pendingDetections() const { return dets_.size(); }
  std::uint64_t timedOut() const { return timed_out_; }  ///< depth maps released without detections
  std::uint64_t late() const { return late_; }           ///< detections that came after their depth left
  /// Detection sets dropped unpaired because max_pending sets waited.
  std::uint64_t detectionsDropped() const { return dets_dropped_; }

 private:
  struct Waiting {
    std::uint64_t stamp;
    double arrival;
    Depth depth;
    std::optional<Dets> dets;
  };
  Pair releaseFront(bool queue_full) {
    Waiting& w = depth_.front();
    Pair p{w.stamp, std::move(w.depth), std::move(w.dets), false};
    if (!p.dets) {
      p.queue_full = queue_full;
      released_[w.stamp] = true;
      if (released_.size() > 4 * max_pending_) released_.erase(released_.begin());
      ++timed_out_;
    }
    depth_.pop_front();
    return p;
  }
  double wait_s_;
  std::size_t max_pending_;
  std::deque<Waiting> depth_;
  std::map<std::uint64_t, Dets> dets_;
  std::map<std::uint64_t, bool> released_;
  std::uint64_t timed_out_ = 0, late_ = 0, dets_dropped_ = 0;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_DETECTION_DEPTH_MASK_H_
