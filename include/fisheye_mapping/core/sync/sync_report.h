// The frame-set sync stage's bookkeeping besides the grouping (FrameSetSync):
// which topics feed which rig camera, whether an image fits its camera, each
// camera's arrivals (rate, bad images, silence), the sync's counters as drops
// by reason and as the values /diagnostics shows. No ROS: the sync nodelet
// passes ROS time as seconds.
#ifndef FISHEYE_MAPPING_CORE_SYNC_SYNC_REPORT_H_
#define FISHEYE_MAPPING_CORE_SYNC_SYNC_REPORT_H_

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/common/stage_stats.h"

namespace fisheye_mapping {

/// The image topics of the rig's cameras, in camera order: `topics` when
/// given, else each camera's camchain rostopic. Throws CalibrationError naming
/// a camera without a rostopic (set ~image_topics) or a count of topics that
/// is not the count of cameras.
std::vector<std::string> imageTopicsForRig(const Rig& rig, std::vector<std::string> topics);

/// Why an image of width x height cannot be a picture of `camera` (its
/// calibration says another size), or nullopt when it fits.
std::optional<std::string> imageSizeMismatch(int width, int height, const std::string& encoding,
                                             const CameraModel& camera);

/// The drops between two readings of a FrameSetSync's Stats, one reason per
/// drop ("incomplete set", "out-of-order image", "stale image (old timeline)").
template <class Stats>
std::vector<std::string> newSyncDrops(const Stats& before, const Stats& now) {
  std::vector<std::string> out;
  for (auto n = before.dropped_incomplete; n < now.dropped_incomplete; ++n) out.push_back("incomplete set");
  for (auto n = before.dropped_out_of_order; n < now.dropped_out_of_order; ++n) out.push_back("out-of-order image");
  for (auto n = before.dropped_stale; n < now.dropped_stale; ++n) out.push_back("stale image (old timeline)");
  return out;
}

/// The sync's counters as /diagnostics shows them, in order. Every frame set
/// by what became of it: "frame sets out" + "frame sets dropped" = the sets seen.
template <class Stats>
std::vector<std::pair<std::string, std::uint64_t>> syncReportValues(const Stats& s) {
  return {{"frame sets out", s.complete},
          {"frame sets dropped", s.setsDropped()},
          {"frame sets dropped: stamps backwards", s.sets_backwards},
          {"frame sets dropped: duplicate stamp", s.sets_duplicate},
          {"frame sets dropped: incomplete", s.dropped_incomplete},
          {"frame sets dropped: old timeline", s.sets_stale},
          {"incomplete sets dropped", s.dropped_incomplete},
          {"out-of-order images dropped", s.dropped_out_of_order},
          {"stale images dropped (old timeline)", s.dropped_stale}};
}

/// Each camera's arrivals: counts, input rate (StageStats, steady clock),
/// bad images, and silence against the stage's clock (ROS time in seconds;
/// 0 means "no clock yet", as ros::Time under sim time before /clock). Not
/// thread-safe.
class CameraActivity {
 public:
  CameraActivity(int cameras, double window_s);

  /// An image from `cam` arrived at `now_s`.
  void arrived(int cam, double now_s);
  void bad(int cam) { ++cams_.at(std::size_t(cam)).bad; }
  /// Listening began (subscribed) at `now_s`: a camera without an image is
  /// silent from here.
  void listening(double now_s) { started_ = now_s; }
  /// The clock went back to `now_s`: arrival times, now ahead of it, start there.
  void clockWentBack(double now_s);
  /// The cameras silent for more than `silent_s` at `now_s`: since their last
  /// image, or since listening began when none came. A clock not yet known
  /// when listening began is taken from this call.
  std::vector<int> silent(double now_s, double silent_s);

  int cameras() const { return int(cams_.size()); }
  std::uint64_t received(int cam) const { return cams_.at(std::size_t(cam)).received; }
  std::uint64_t badImages(int cam) const { return cams_.at(std::size_t(cam)).bad; }
  double rateHz(int cam) const { return cams_.at(std::size_t(cam)).stats->snapshot().input.rate_hz; }

 private:
  struct Camera {
    std::uint64_t received = 0, bad = 0;
    double last_arrival = 0;
    std::unique_ptr<StageStats> stats;
  };
  std::vector<Camera> cams_;
  double started_ = 0;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_SYNC_SYNC_REPORT_H_
