// What one pipeline stage did lately, for its diagnostics: input and output
// rates, processing times, drops by reason and tf lookup failures, each over a
// sliding window of steady-clock time (10 s by default) and since the start.
//
// Times are steady-clock seconds passed by the caller (tests replay exact
// times); each recording method also has an overload that reads
// std::chrono::steady_clock itself (now()).
//
// Rates are estimated from the event times in the window, not from counts per
// reporting period: a 1 Hz stream reported every second otherwise reads 0 or 2
// Hz (or 0 and 1) by the phase of the two clocks. With n >= 2 events in the
// window, first at t0, last at t1, and the reading at `now`:
//   rate = min((n - 1) / (t1 - t0),  n / (now - t0))
// The first term is the mean interval of the window; the second takes over once
// the gap since the last event is longer than that mean interval (the stream
// slowed or stopped), so a stalled stream's rate falls as its events leave the
// window and is 0 once fewer than 2 remain. For a steady stream both terms are
// equal at the phase where the next event is due, so readings at any phase
// agree. Thread-safe.
#ifndef FISHEYE_MAPPING_CORE_COMMON_STAGE_STATS_H_
#define FISHEYE_MAPPING_CORE_COMMON_STAGE_STATS_H_

#include <cstdint>
#include <deque>
#include <map>
#include <mutex>
#include <string>
#include <utility>

namespace fisheye_mapping {

/// All figures of a StageStats at one time ("window": the last window_s
/// seconds before that time; "total": since the start).
struct StageStatsSnapshot {
  struct Stream {
    std::uint64_t total = 0;   ///< events since the start
    std::uint64_t window = 0;  ///< events in the window
    double rate_hz = 0;        ///< see the file comment; 0 with fewer than 2 events in the window
    double age_s = -1;         ///< seconds since the latest event; -1 when there was none
  };
  struct Processing {
    std::uint64_t total = 0;   ///< processed() calls since the start
    std::uint64_t window = 0;  ///< of them in the window
    double last_s = 0;         ///< the latest time, in or out of the window; 0 when none
    double mean_s = 0, max_s = 0;  ///< over the window; 0 when none
  };
  struct Count {
    std::uint64_t total = 0, window = 0;
  };
  double window_s = 0;
  Stream input, output;
  Processing processing;
  std::map<std::string, Count> dropped;  ///< by reason; a reason seen once stays listed
  Count dropped_all;                     ///< all reasons together
  Count tf_failures;
  std::string last_tf_failure;  ///< empty when none
};

class StageStats {
 public:
  /// Throws std::invalid_argument unless window_s > 0.
  explicit StageStats(double window_s = 10.0);

  /// Steady-clock seconds (the time base of every method here).
  static double now();

  void input(double t);
  void input() { input(now()); }
  void output(double t);
  void output() { output(now()); }
  /// One item processed in `seconds` (e.g. a frame set's wall time in the stage).
  void processed(double seconds, double t);
  void processed(double seconds) { processed(seconds, now()); }
  /// One item dropped or skipped, e.g. "no pose", "queue full".
  void dropped(const std::string& reason, double t);
  void dropped(const std::string& reason) { dropped(reason, now()); }
  /// One tf lookup that failed; `what` is kept as the latest message.
  void tfFailure(const std::string& what, double t);
  void tfFailure(const std::string& what) { tfFailure(what, now()); }

  double windowSeconds() const { return window_s_; }
  StageStatsSnapshot snapshot(double now) const;
  StageStatsSnapshot snapshot() const { return snapshot(now()); }

 private:
  struct Events {
    std::uint64_t total = 0;
    std::deque<double> times;  // sorted; only the window's (pruned on insert)
  };
  void add(Events& e, double t) const;
  StageStatsSnapshot::Stream stream(const Events& e, double now) const;

  double window_s_;
  mutable std::mutex mutex_;
  Events inputs_, outputs_, tf_failures_;
  std::uint64_t processed_total_ = 0;
  double processed_last_ = 0;
  std::deque<std::pair<double, double>> processing_;  // (time, seconds)
  std::map<std::string, std::uint64_t> dropped_total_;
  std::deque<std::pair<double, std::string>> drops_;  // (time, reason) in the window
  std::string last_tf_failure_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_STAGE_STATS_H_
