// Time going backwards on streams that share one timeline: the one unit every
// stage uses for time resets (a bag played again, a simulation restarted, a
// clock that jumped back). Header-only, no ROS: the sync (cameras), the depth
// stage (frame sets), the mask (depth maps and detections) and the TSDF
// (depth frames) each hold a StreamTimeline whose threshold is their
// `time_reset_threshold` parameter (seconds; 0: never).
#ifndef FISHEYE_MAPPING_CORE_COMMON_STREAM_TIMELINE_H_
#define FISHEYE_MAPPING_CORE_COMMON_STREAM_TIMELINE_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace fisheye_mapping {

/// A stamp in seconds with millisecond digits, for messages ("1234.567").
inline std::string formatStamp(std::int64_t ns) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.3f", double(ns) * 1e-9);
  return buf;
}

/// Time going backwards on a set of streams that share one timeline (the
/// cameras of a rig; depth maps and detections of the same images).
///
/// Each stream's stamps normally increase. A stamp older than its stream's
/// newest by more than `threshold_s` resets the timeline (observe() returns
/// kReset with the old and new stamps and a reason): the caller clears every
/// state keyed on time. After a reset, the other streams are on the old
/// timeline until they show a stamp not ahead of the new timeline's newest by
/// more than the threshold (kJoined, then kOk); their stamps before that are
/// stragglers of the old timeline (kStale: drop them). A stream that stays
/// ahead for more than 3 thresholds of its own time is not straggling: it
/// joins. clock() resets when the newest stamp is ahead of a clock that jumped
/// back. A threshold <= 0 (or not finite) disables resets: every stamp is kOk.
/// Not thread-safe.
class StreamTimeline {
 public:
  enum class Kind { kOk, kReset, kJoined, kStale };
  struct Event {
    Kind kind = Kind::kOk;
    std::int64_t from_ns = 0;  ///< kReset: the newest stamp before (the stream's, or the clock check's newest)
    std::int64_t to_ns = 0;    ///< kReset: the stamp (or clock) that went back
    std::string reason;        ///< kReset: what happened, for logs and diagnostics
  };

  StreamTimeline(int streams, double threshold_s) : streams_(std::max(0, streams)) {
    if (streams < 1) throw std::invalid_argument("stream timeline: need at least one stream");
    if (std::isfinite(threshold_s) && threshold_s > 0) threshold_ns_ = std::int64_t(threshold_s * 1e9);
  }

  bool enabled() const { return threshold_ns_ > 0; }
  double thresholdSeconds() const { return threshold_ns_ * 1e-9; }

  Event observe(int stream, std::int64_t stamp_ns) {
    if (stream < 0 || stream >= int(streams_.size())) throw std::out_of_range("stream timeline: stream index out of range");
    Event e;
    if (!enabled()) return e;
    Stream& s = streams_[stream];
    if (s.epoch != epoch_) {
      // On the old timeline until its stamps come near the new one.
      if (newest_ && stamp_ns > *newest_ + threshold_ns_) {
        if (!s.stale_first) s.stale_first = stamp_ns;
        if (stamp_ns - *s.stale_first <= 3 * threshold_ns_) {
          ++stale_;
          e.kind = Kind::kStale;
          s.newest = s.newest ? std::max(*s.newest, stamp_ns) : stamp_ns;
          return e;
        }
      }
      s.epoch = epoch_;
      s.stale_first.reset();
      s.newest = stamp_ns;
      newest_ = newest_ ? std::max(*newest_, stamp_ns) : stamp_ns;
      e.kind = Kind::kJoined;
      return e;
    }
    if (s.newest && stamp_ns < *s.newest - threshold_ns_) {
      e.kind = Kind::kReset;
      e.from_ns = *s.newest;
      e.to_ns = stamp_ns;
      e.reason = "time went backwards: stamp " + formatStamp(stamp_ns) + " s is " +
                 formatStamp(*s.newest - stamp_ns) + " s older than the newest " + formatStamp(*s.newest) +
                 " s (threshold " + formatStamp(threshold_ns_) +
                 " s; a bag played again, the player restarted or the clock reset?)";
      startEpoch(stamp_ns);
      s.epoch = epoch_;
      s.newest = stamp_ns;
      return e;
    }
    s.newest = s.newest ? std::max(*s.newest, stamp_ns) : stamp_ns;
    newest_ = newest_ ? std::max(*newest_, stamp_ns) : stamp_ns;
    return e;
  }

  /// The clock now (e.g. ROS time under sim time; never call it with a zero
  /// "no clock yet"): a reset when the newest stamp is ahead of it by more
  /// than the threshold (the clock jumped back under the streams).
  std::optional<Event> clock(std::int64_t now_ns) {
    if (!enabled() || !newest_ || *newest_ <= now_ns + threshold_ns_) return std::nullopt;
    Event e;
    e.kind = Kind::kReset;
    e.from_ns = *newest_;
    e.to_ns = now_ns;
    e.reason = "clock jumped backwards: now " + formatStamp(now_ns) + " s, " + formatStamp(*newest_ - now_ns) +
               " s before the newest stamp " + formatStamp(*newest_) + " s (threshold " +
               formatStamp(threshold_ns_) + " s; a bag played again or the simulation restarted?)";
    startEpoch(std::nullopt);  // the first stamp to come sets the new timeline
    return e;
  }

  /// Forgets every stamp (as at construction; counts are kept).
  void reset() {
    for (auto& s : streams_) s = Stream{};
    epoch_ = 0;
    newest_.reset();
  }

  std::uint64_t resets() const { return resets_; }
  std::uint64_t stale() const { return stale_; }  ///< stamps dropped as stragglers of an old timeline
  std::optional<std::int64_t> newest() const { return newest_; }

 private:
  struct Stream {
    std::uint64_t epoch = 0;
    std::optional<std::int64_t> newest, stale_first;
  };
  void startEpoch(std::optional<std::int64_t> newest) {
    ++epoch_;
    ++resets_;
    newest_ = newest;
    for (auto& s : streams_) s.stale_first.reset();
  }

  std::vector<Stream> streams_;
  std::int64_t threshold_ns_ = 0;
  std::uint64_t epoch_ = 0, resets_ = 0, stale_ = 0;
  std::optional<std::int64_t> newest_;  // newest stamp of the streams on the current timeline
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_STREAM_TIMELINE_H_
