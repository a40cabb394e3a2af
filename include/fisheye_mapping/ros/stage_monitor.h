// One stage's /diagnostics: a diagnostic_updater::Updater with one task named
// after the stage, reporting a core StageStats (rates over a sliding window,
// processing times, drops by reason, tf lookup failures) and a StageHealth
// (callback errors, time resets), plus whatever the stage adds itself.
//
// In a nodelet (replaces the Updater + wall timer + diagnose() pattern):
//   monitor_ = std::make_unique<StageMonitor>(getNodeHandle(), getPrivateNodeHandle(), "depth");
//   monitor_->input();                  // a message arrived
//   monitor_->processed(seconds);       // time spent on it
//   monitor_->output();                 // a result published
//   monitor_->dropped("no pose");       // skipped, by reason
//   monitor_->tfFailure(e.what());      // a failed tf lookup
//   monitor_->error(...), timeReset(...) // StageHealth, as before
//
// Values: "input rate (Hz)", "output rate (Hz)", "inputs", "outputs",
// "last input (s ago)", "processing time last/mean/max (ms)",
// "dropped: <reason>" per reason, "tf failures" (+ "last tf failure"), the
// StageHealth values, then the stage's extras. Summary OK ("running", or
// "waiting for input" before the first input); WARN, with a message naming
// each cause, when the input stalled (none for more than 3 expected periods
// after inputs had arrived, while input is expected), when items were dropped
// or tf lookups failed within the window, or when StageHealth warns.
//
// Parameters (private): ~hardware_id (default: the node's name),
// ~diagnostic_period (s between reports, diagnostic_updater's own),
// ~diagnostic_window (s, the StageStats window), ~diagnostic_expected_period
// (s between inputs in normal operation). Thread-safe, except that the extra
// report callback runs on the reporting timer's thread.
#ifndef FISHEYE_MAPPING_ROS_STAGE_MONITOR_H_
#define FISHEYE_MAPPING_ROS_STAGE_MONITOR_H_

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>

#include "fisheye_mapping/core/common/params.h"
#include "fisheye_mapping/core/common/stage_stats.h"
#include "fisheye_mapping/ros/stage_health.h"

namespace fisheye_mapping {

/// StageMonitor::Options (outside the class: a nested struct with member
/// initializers cannot be a default argument of its enclosing class).
struct StageMonitorOptions {
  double window_s = 10.0;          ///< ~diagnostic_window
  double expected_period_s = 1.0;  ///< ~diagnostic_expected_period; stalled after 3 of them
  /// Reads the parameters above over `defaults`; throws std::invalid_argument
  /// naming the parameter unless each is a positive number.
  static StageMonitorOptions fromParams(const ParamSource& params, StageMonitorOptions defaults);
  static StageMonitorOptions fromParams(const ParamSource& params);
};

class StageMonitor {
 public:
  using Options = StageMonitorOptions;
  /// Input silent for this many expected periods: stalled.
  static constexpr double kStallPeriods = 3.0;
  using ExtraReport = std::function<void(diagnostic_updater::DiagnosticStatusWrapper&)>;

  /// Without ROS: no Updater, no timer; fill() reports (tests, offline use).
  explicit StageMonitor(std::string stage_name, Options options = {});
  /// For a nodelet: an Updater on `nh`/`pnh` publishing the task `stage_name`
  /// every ~diagnostic_period on a wall timer (so it reports while a bag's
  /// clock is paused); the parameters override `defaults`. Throws
  /// std::invalid_argument for a bad parameter.
  StageMonitor(ros::NodeHandle nh, ros::NodeHandle pnh, std::string stage_name, Options defaults = {});
  ~StageMonitor();
  StageMonitor(const StageMonitor&) = delete;
  StageMonitor& operator=(const StageMonitor&) = delete;

  // StageStats, on the steady clock.
  void input() { stats_.input(); }
  void output() { stats_.output(); }
  void processed(double seconds) { stats_.processed(seconds); }
  void dropped(const std::string& reason) { stats_.dropped(reason); }
  void tfFailure(const std::string& what) { stats_.tfFailure(what); }
  // StageHealth.
  void error(const std::string& what) { health_.error(what); }
  void timeReset(const std::string& reason) { health_.timeReset(reason); }

  /// False while the stage does not expect input (e.g. it unsubscribed because
  /// nobody listens to its output): silence is then not a stall.
  void setInputExpected(bool expected) { input_expected_ = expected; }
  /// Adds the stage's own values (and summaries, with mergeSummary) after the
  /// standard ones, e.g. the TSDF's block counts. Runs on the reporting thread.
  void setExtraReport(ExtraReport report);

  /// Writes the summary and the values for steady-clock time `now`
  /// (StageStats::now()).
  void fill(diagnostic_updater::DiagnosticStatusWrapper& stat, double now) const;

  const std::string& stageName() const { return stage_; }
  const Options& options() const { return options_; }
  StageStats& stats() { return stats_; }
  StageHealth& health() { return health_; }
  /// The Updater (nullptr without ROS): to set another hardware id, add tasks
  /// or force_update() after a notable event.
  diagnostic_updater::Updater* updater() { return updater_.get(); }

 private:
  void report(diagnostic_updater::DiagnosticStatusWrapper& stat);
  void warn(diagnostic_updater::DiagnosticStatusWrapper& stat, const StageStatsSnapshot& s) const;
  void publish();

  std::string stage_;
  Options options_;
  StageStats stats_;
  StageHealth health_;
  std::atomic<bool> input_expected_{true};
  mutable std::mutex extra_mutex_;
  ExtraReport extra_;
  std::unique_ptr<diagnostic_updater::Updater> updater_;
  double period_s_ = 0;   // the timer's, to follow ~diagnostic_period
  ros::WallTimer timer_;  // last: stopped before the rest goes
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_STAGE_MONITOR_H_
