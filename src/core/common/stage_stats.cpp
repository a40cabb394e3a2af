#include "fisheye_mapping/core/common/stage_stats.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "fisheye_mapping/core/common/params.h"

namespace fisheye_mapping {

namespace {

// Drops the entries older than the window before `t` from a deque of
// (time, value) kept in arrival order.
template <class T>
void pruneBefore(std::deque<std::pair<double, T>>& d, double t) {
  while (!d.empty() && d.front().first < t) d.pop_front();
}

}  // namespace

StageStats::StageStats(double window_s) : window_s_(window_s) {
  requireField(std::isfinite(window_s) && window_s > 0, "StageStats window_s", "must be a positive number of seconds",
               window_s);
}

double StageStats::now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Events from several threads may arrive slightly out of time order (each took
// its time before the lock): inserting in order keeps first/last exact.
void StageStats::add(Events& e, double t) const {
  ++e.total;
  e.times.insert(std::upper_bound(e.times.begin(), e.times.end(), t), t);
  const double oldest = e.times.back() - window_s_;
  while (!e.times.empty() && e.times.front() < oldest) e.times.pop_front();
}

void StageStats::input(double t) {
  std::lock_guard<std::mutex> l(mutex_);
  add(inputs_, t);
}

void StageStats::output(double t) {
  std::lock_guard<std::mutex> l(mutex_);
  add(outputs_, t);
}

void StageStats::processed(double seconds, double t) {
  std::lock_guard<std::mutex> l(mutex_);
  ++processed_total_;
  processed_last_ = seconds;
  processing_.emplace_back(t, seconds);
  pruneBefore(processing_, t - window_s_);
}

void StageStats::dropped(const std::string& reason, double t) {
  std::lock_guard<std::mutex> l(mutex_);
  ++dropped_total_[reason];
  drops_.emplace_back(t, reason);
  pruneBefore(drops_, t - window_s_);
}

void StageStats::tfFailure(const std::string& what, double t) {
  std::lock_guard<std::mutex> l(mutex_);
  add(tf_failures_, t);
  last_tf_failure_ = what;
}

StageStatsSnapshot::Stream StageStats::stream(const Events& e, double now) const {
  StageStatsSnapshot::Stream s;
  s.total = e.total;
  if (e.times.empty()) return s;
  const double from = now - window_s_;
  const auto first = std::lower_bound(e.times.begin(), e.times.end(), from);
  s.window = std::uint64_t(e.times.end() - first);
  // A reading taken before the latest event (a caller's stale `now`) counts as
  // taken at it.
  const double t1 = e.times.back(), at = std::max(now, t1);
  s.age_s = at - t1;
  if (s.window < 2) return s;
  const double t0 = *first, n = double(s.window);
  const double span = t1 - t0, open = at - t0;
  if (open <= 0) return s;  // all at one instant: no rate yet
  s.rate_hz = n / open;
  if (span > 0) s.rate_hz = std::min(s.rate_hz, (n - 1) / span);
  return s;
}

StageStatsSnapshot StageStats::snapshot(double now) const {
  std::lock_guard<std::mutex> l(mutex_);
  const double from = now - window_s_;
  StageStatsSnapshot s;
  s.window_s = window_s_;
  s.input = stream(inputs_, now);
  s.output = stream(outputs_, now);

  auto& p = s.processing;
  p.total = processed_total_;
  p.last_s = processed_last_;
  double sum = 0;
  for (const auto& [t, seconds] : processing_) {
    if (t < from) continue;
    ++p.window;
    sum += seconds;
    p.max_s = p.window == 1 ? seconds : std::max(p.max_s, seconds);
  }
  if (p.window) p.mean_s = sum / double(p.window);

  for (const auto& [reason, total] : dropped_total_) {
    s.dropped[reason].total = total;
    s.dropped_all.total += total;
  }
  for (const auto& [t, reason] : drops_) {
    if (t < from) continue;
    ++s.dropped[reason].window;
    ++s.dropped_all.window;
  }

  const auto tf = stream(tf_failures_, now);
  s.tf_failures.total = tf.total;
  s.tf_failures.window = tf.window;
  s.last_tf_failure = last_tf_failure_;
  return s;
}

}  // namespace fisheye_mapping
