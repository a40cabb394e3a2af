// Grouping the images of N cameras into synchronized frame sets (no ROS), and
// noticing when time goes backwards (StreamTimeline).
//
// message_filters' Synchronizer takes at most 9 inputs; this groups any number
// of cameras. Policies:
//   exact        images belong together when their stamps are equal;
//   approximate  an image joins the oldest open set that lacks its camera and
//                whose first stamp is within max_interval of its own.
// A set is published when every camera has an image. Open sets older than a
// completed one, and the oldest open sets beyond the queue size, can no longer
// complete (each camera's stamps increase) and are dropped and counted. An
// image older than the last published set is dropped as out of order.
//
// Time going backwards (a bag played again, `rosbag play` restarted, a
// simulator's clock reset): a camera's stamp older than that camera's newest
// by more than the time-reset threshold (default 1 s) starts a new timeline:
// the sync forgets its open sets and the last published stamp, counts a time
// reset and keeps its reason (lastTimeReset()), and goes on grouping. Smaller
// steps back (jitter, a late image) are dropped as out of order as before.
// Images of the other cameras that still belong to the old timeline (stamps
// ahead of the new one by more than the threshold: in flight when the reset
// happened) are dropped as stale until that camera's stamps join the new
// timeline. A clock that jumps backwards under the stream (clockAt(): the ROS
// clock under sim time) resets the same way.
//
// Every frame set is accounted for (Stats::sets*): each frame set the images
// make up is either complete or dropped for one reason, counted once: stamps
// backwards (an image older than the last published set), duplicate stamp (a
// camera's image with the stamp of its previous one), incomplete (an open set
// that can no longer complete, or is open at finish()) or stale (an old
// timeline's straggler). A dropped image that fits a frame set already
// dropped (the late image of a set dropped as incomplete, the other cameras
// of a duplicated stamp) joins that set and is not counted again, so
// complete + the drops = the frame sets in the stream.
#ifndef FISHEYE_MAPPING_CORE_SYNC_FRAME_SYNC_H_
#define FISHEYE_MAPPING_CORE_SYNC_FRAME_SYNC_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "fisheye_mapping/core/common/stream_timeline.h"

namespace fisheye_mapping {

class ParamSource;

enum class SyncPolicy { Exact, Approximate };  // "exact" | "approximate"

/// Throws std::invalid_argument naming the parameter (policy), the allowed
/// values and the bad one.
inline SyncPolicy parseSyncPolicy(const std::string& s) {
  if (s == "exact") return SyncPolicy::Exact;
  if (s == "approximate") return SyncPolicy::Approximate;
  throw std::invalid_argument("policy: must be 'exact' or 'approximate', got '" + s + "'");
}

inline std::string toString(SyncPolicy p) {
  switch (p) {
    case SyncPolicy::Exact: return "exact";
    case SyncPolicy::Approximate: return "approximate";
  }
  return "?";
}

/// The frame-set sync stage's parameters (the frame sync nodelet's, and the
/// sync section of config/vehicle.yaml).
template <class Config>
class ParamTable;  // fisheye_mapping/core/common/param_table.h

struct FrameSyncConfig {
  SyncPolicy policy = SyncPolicy::Exact;  ///< parameter policy: "exact" | "approximate"
  double max_interval = 0.005;            ///< s, approximate policy; >= 0
  int queue_size = 10;                    ///< open sets; >= 1
  double silent_warning = 2.0;            ///< s without an image before a camera is reported; > 0
  double time_reset_threshold = 1.0;      ///< s a camera may step back before the sync resets; 0: never
  /// One image topic per camera, in camera order; empty: the camchain's
  /// rostopics.
  std::vector<std::string> image_topics;

  /// Throws std::invalid_argument naming the parameter and the bad value.
  void validate() const;
  /// The declaration of every parameter (docs/parameters.md).
  static const ParamTable<FrameSyncConfig>& params();
  /// The defaults above (or `base`) overlaid with the parameters of the same
  /// names in `p` (policy as its name, parsed here); validated.
  static FrameSyncConfig fromParams(const ParamSource& p);
  static FrameSyncConfig fromParams(const ParamSource& p, FrameSyncConfig base);
};


template <class T>
class FrameSetSync {
 public:
  struct Set {
    std::int64_t stamp_ns;             ///< stamp of the first image that opened the set
    std::vector<std::optional<T>> items;
    int count = 0;
  };
  struct Stats {
    std::uint64_t complete = 0;            ///< frame sets published
    std::uint64_t dropped_incomplete = 0;  ///< frame sets that could no longer complete
    std::uint64_t dropped_out_of_order = 0;  ///< images older than the last published set, or duplicates
    std::uint64_t time_resets = 0;    ///< timelines restarted (time went backwards)
    std::uint64_t dropped_stale = 0;  ///< images of an old timeline after a reset
    // Frame sets dropped, by reason (each counted once; see the file comment).
    std::uint64_t sets_backwards = 0;  ///< stamps went backwards (older than the last published set)
    std::uint64_t sets_duplicate = 0;  ///< a camera repeated its previous stamp
    std::uint64_t sets_stale = 0;      ///< of an old timeline, after a time reset
    /// Frame sets dropped for any reason (incomplete included).
    std::uint64_t setsDropped() const { return dropped_incomplete + sets_backwards + sets_duplicate + sets_stale; }
    /// Every frame set seen: complete + setsDropped().
    std::uint64_t sets() const { return complete + setsDropped(); }
    Stats& operator+=(const Stats& o) {
      complete += o.complete, dropped_incomplete += o.dropped_incomplete, dropped_out_of_order += o.dropped_out_of_order;
      time_resets += o.time_resets, dropped_stale += o.dropped_stale;
      sets_backwards += o.sets_backwards, sets_duplicate += o.sets_duplicate, sets_stale += o.sets_stale;
      return *this;
    }
  };
  enum class Drop { kBackwards, kDuplicate, kStale };
  struct TimeReset {
    std::int64_t from_ns = 0, to_ns = 0;  ///< newest stamp before, the stamp (or clock) after
    std::string reason;                   ///< includes the open sets dropped
  };

  /// time_reset_s: a camera's stamp older than its newest by more than this
  /// resets the sync (<= 0: never; such images are dropped as out of order).
  FrameSetSync(int cameras, SyncPolicy policy, double max_interval_s, std::size_t queue_size,
               double time_reset_s = 1.0)
      : n_(cameras),
        policy_(policy),
        max_interval_ns_(std::int64_t(max_interval_s * 1e9)),
        queue_(queue_size),
        last_stamp_(std::max(0, cameras)),
        timeline_(std::max(1, cameras), time_reset_s) {
    if (cameras < 1) throw std::invalid_argument("frame sync: need at least one camera");
    if (queue_size < 1) throw std::invalid_argument("frame sync: queue size must be >= 1");
    if (!(max_interval_s >= 0)) throw std::invalid_argument("frame sync: max_interval must be >= 0");
  }

  /// Adds camera `cam`'s image; returns the sets it completed (at most one), items in camera order.
  std::vector<std::vector<T>> add(int cam, std::int64_t stamp_ns, T item) {
    if (cam < 0 || cam >= n_) throw std::out_of_range("frame sync: camera index out of range");
    std::vector<std::vector<T>> out;
    const StreamTimeline::Event ev = timeline_.observe(cam, stamp_ns);
    if (ev.kind == StreamTimeline::Kind::kStale) {
      ++stats_.dropped_stale;
      dropImage(cam, stamp_ns, Drop::kStale);
      return out;
    }
    if (ev.kind == StreamTimeline::Kind::kReset) timeReset(ev, "camera " + std::to_string(cam) + ": ");
    const bool duplicate = last_stamp_[cam] && *last_stamp_[cam] == stamp_ns;
    last_stamp_[cam] = last_stamp_[cam] ? std::max(*last_stamp_[cam], stamp_ns) : stamp_ns;
    if (duplicate) {
      ++stats_.dropped_out_of_order;
      dropImage(cam, stamp_ns, Drop::kDuplicate);
      return out;
    }
    if (last_published_ && stamp_ns <= *last_published_ - (policy_ == SyncPolicy::Exact ? 0 : max_interval_ns_)) {
      ++stats_.dropped_out_of_order;
      dropImage(cam, stamp_ns, Drop::kBackwards);
      return out;
    }
    auto target = open_.end();
    for (auto it = open_.begin(); it != open_.end(); ++it) {
      if (it->items[cam] || !matches(it->stamp_ns, stamp_ns)) continue;
      target = it;
      break;
    }
    if (target == open_.end()) {
      Set s;
      s.stamp_ns = stamp_ns;
      s.items.resize(n_);
      // Keep the open sets ordered by stamp.
      auto it = open_.begin();
      while (it != open_.end() && it->stamp_ns <= stamp_ns) ++it;
      target = open_.insert(it, std::move(s));
    }
    target->items[cam] = std::move(item);
    ++target->count;
    if (target->count == n_) {
      const std::int64_t done = target->stamp_ns;
      std::vector<T> items;
      items.reserve(n_);
      for (auto& i : target->items) items.push_back(std::move(*i));
      out.push_back(std::move(items));
      open_.erase(target);
      // Everything opened before the completed set can no longer complete.
      while (!open_.empty() && open_.front().stamp_ns <= done) dropOpenFront();
      last_published_ = done;
      ++stats_.complete;
    }
    while (open_.size() > queue_) dropOpenFront();
    return out;
  }

  /// The end of the stream (a bag read to its end): the open sets can no
  /// longer complete and are counted as incomplete.
  void finish() {
    while (!open_.empty()) dropOpenFront();
  }

  /// The clock now (ROS time under sim time; not zero): resets when the newest
  /// image is ahead of it by more than the threshold. Returns the reset.
  std::optional<TimeReset> clockAt(std::int64_t now_ns) {
    if (auto ev = timeline_.clock(now_ns)) {
      timeReset(*ev, "");
      return last_reset_;
    }
    return std::nullopt;
  }

  /// Forgets the open sets (counted as incomplete) and every stamp seen, as if
  /// just constructed; the counts are kept.
  void reset() {
    finish();
    last_published_.reset();
    std::fill(last_stamp_.begin(), last_stamp_.end(), std::nullopt);
    timeline_.reset();
  }

  const Stats& stats() const { return stats_; }
  std::size_t open() const { return open_.size(); }
  /// The latest time reset (empty before the first).
  const std::optional<TimeReset>& lastTimeReset() const { return last_reset_; }

 private:
  // Images of one frame set: equal stamps (exact) or within max_interval.
  bool matches(std::int64_t set_ns, std::int64_t stamp_ns) const {
    const std::int64_t d = std::llabs(stamp_ns - set_ns);
    return policy_ == SyncPolicy::Exact ? d == 0 : d <= max_interval_ns_;
  }

  // A frame set dropped: its stamp and the cameras whose images it had.
  struct DroppedSet {
    std::int64_t stamp_ns;
    std::vector<bool> cams;
  };
  void remember(DroppedSet d) {
    dropped_.push_back(std::move(d));
    while (dropped_.size() > queue_ + std::size_t(n_)) dropped_.pop_front();
  }

  // The oldest open set can no longer complete: counted as incomplete.
  void dropOpenFront() {
    DroppedSet d{open_.front().stamp_ns, std::vector<bool>(n_)};
    for (int c = 0; c < n_; ++c) d.cams[c] = bool(open_.front().items[c]);
    open_.pop_front();
    ++stats_.dropped_incomplete;
    remember(std::move(d));
  }

  // An image dropped: it joins a dropped frame set that lacks its camera, or
  // is the first image of a frame set dropped for `why`.
  void dropImage(int cam, std::int64_t stamp_ns, Drop why) {
    for (auto it = dropped_.rbegin(); it != dropped_.rend(); ++it) {
      if (it->cams[cam] || !matches(it->stamp_ns, stamp_ns)) continue;
      it->cams[cam] = true;
      return;
    }
    DroppedSet d{stamp_ns, std::vector<bool>(n_)};
    d.cams[cam] = true;
    remember(std::move(d));
    ++(why == Drop::kBackwards ? stats_.sets_backwards : why == Drop::kDuplicate ? stats_.sets_duplicate
                                                                                 : stats_.sets_stale);
  }

  void timeReset(const StreamTimeline::Event& ev, const std::string& who) {
    const std::size_t dropped = open_.size();
    finish();  // kept among the dropped sets: the old timeline's stragglers join them
    std::fill(last_stamp_.begin(), last_stamp_.end(), std::nullopt);
    last_published_.reset();
    ++stats_.time_resets;
    last_reset_ = TimeReset{ev.from_ns, ev.to_ns,
                            who + ev.reason + "; frame sync reset, " + std::to_string(dropped) + " open set(s) dropped"};
  }

  int n_;
  SyncPolicy policy_;
  std::int64_t max_interval_ns_;
  std::size_t queue_;
  std::deque<Set> open_;
  std::deque<DroppedSet> dropped_;  // the latest frame sets dropped
  std::vector<std::optional<std::int64_t>> last_stamp_;  // each camera's newest stamp
  std::optional<std::int64_t> last_published_;
  StreamTimeline timeline_;
  std::optional<TimeReset> last_reset_;
  Stats stats_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_SYNC_FRAME_SYNC_H_
