// Grouping the images of N cameras into synchronized frame sets (no ROS).
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
#pragma once

#include <cstdint>
#include <cstdlib>
#include <deque>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace fisheye_mapping {

enum class SyncPolicy { Exact, Approximate };

inline SyncPolicy parseSyncPolicy(const std::string& s) {
  if (s == "exact") return SyncPolicy::Exact;
  if (s == "approximate") return SyncPolicy::Approximate;
  throw std::invalid_argument("sync policy '" + s + "' is neither exact nor approximate");
}

template <class T>
class FrameSetSync {
 public:
  struct Set {
    std::int64_t stamp_ns;             ///< stamp of the first image that opened the set
    std::vector<std::optional<T>> items;
    int count = 0;
  };
  struct Stats {
    std::uint64_t complete = 0, dropped_incomplete = 0, dropped_out_of_order = 0;
  };

  FrameSetSync(int cameras, SyncPolicy policy, double max_interval_s, std::size_t queue_size)
      : n_(cameras), policy_(policy), max_interval_ns_(std::int64_t(max_interval_s * 1e9)), queue_(queue_size) {
    if (cameras < 1) throw std::invalid_argument("frame sync: need at least one camera");
    if (queue_size < 1) throw std::invalid_argument("frame sync: queue size must be >= 1");
    if (!(max_interval_s >= 0)) throw std::invalid_argument("frame sync: max_interval must be >= 0");
  }

  /// Adds camera `cam`'s image; returns the sets it completed (at most one), items in camera order.
  std::vector<std::vector<T>> add(int cam, std::int64_t stamp_ns, T item) {
    if (cam < 0 || cam >= n_) throw std::out_of_range("frame sync: camera index out of range");
    std::vector<std::vector<T>> out;
    if (last_published_ && stamp_ns <= *last_published_ - (policy_ == SyncPolicy::Exact ? 0 : max_interval_ns_)) {
      ++stats_.dropped_out_of_order;
      return out;
    }
    Set* target = nullptr;
    for (auto& s : open_) {
      if (s.items[cam]) continue;
      const std::int64_t d = std::llabs(stamp_ns - s.stamp_ns);
      if ((policy_ == SyncPolicy::Exact && d == 0) || (policy_ == SyncPolicy::Approximate && d <= max_interval_ns_)) {
        target = &s;
        break;
      }
    }
    if (!target) {
      Set s;
      s.stamp_ns = stamp_ns;
      s.items.resize(n_);
      // Keep the open sets ordered by stamp.
      auto it = open_.begin();
      while (it != open_.end() && it->stamp_ns <= stamp_ns) ++it;
      target = &*open_.insert(it, std::move(s));
    }
    target->items[cam] = std::move(item);
    ++target->count;
    if (target->count == n_) {
      const std::int64_t done = target->stamp_ns;
      std::vector<T> items;
      items.reserve(n_);
      for (auto& i : target->items) items.push_back(std::move(*i));
      out.push_back(std::move(items));
      // Everything opened before the completed set can no longer complete.
      while (!open_.empty() && open_.front().stamp_ns <= done) {
        if (open_.front().stamp_ns != done) ++stats_.dropped_incomplete;
        open_.pop_front();
      }
      last_published_ = done;
      ++stats_.complete;
    }
    while (open_.size() > queue_) {
      open_.pop_front();
      ++stats_.dropped_incomplete;
    }
    return out;
  }

  const Stats& stats() const { return stats_; }
  std::size_t open() const { return open_.size(); }

 private:
  int n_;
  SyncPolicy policy_;
  std::int64_t max_interval_ns_;
  std::size_t queue_;
  std::deque<Set> open_;
  std::optional<std::int64_t> last_published_;
  Stats stats_;
};

}  // namespace fisheye_mapping
