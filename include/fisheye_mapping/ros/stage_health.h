// What a stage reports about its own health on /diagnostics besides its
// counts: callback errors (an exception caught, the frame skipped, the stage
// going on) and time resets (time went backwards: the stage's time state was
// cleared). Either makes the stage's diagnostics WARN for `warn_s` seconds of
// wall time; the counts and the latest message stay in the values.
// Thread-safe.
#ifndef FISHEYE_MAPPING_ROS_STAGE_HEALTH_H_
#define FISHEYE_MAPPING_ROS_STAGE_HEALTH_H_

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>

#include <cstdint>
#include <mutex>
#include <string>

namespace fisheye_mapping {

class StageHealth {
 public:
  explicit StageHealth(double warn_s = 15.0) : warn_s_(warn_s) {}

  void error(const std::string& what) {
    std::lock_guard<std::mutex> l(mutex_);
    ++errors_;
    last_error_ = what;
    last_error_time_ = ros::WallTime::now();
  }
  void timeReset(const std::string& reason) {
    std::lock_guard<std::mutex> l(mutex_);
    ++resets_;
    last_reset_ = reason;
    last_reset_time_ = ros::WallTime::now();
  }
  std::uint64_t errors() const {
    std::lock_guard<std::mutex> l(mutex_);
    return errors_;
  }
  std::uint64_t resets() const {
    std::lock_guard<std::mutex> l(mutex_);
    return resets_;
  }

  /// Adds the values ("time resets", "last time reset", "callback errors",
  /// "last callback error") and merges WARN while a reset or an error is recent.
  void report(diagnostic_updater::DiagnosticStatusWrapper& stat) const {
    std::lock_guard<std::mutex> l(mutex_);
    const ros::WallTime now = ros::WallTime::now();
    stat.add("time resets", resets_);
    if (resets_) stat.add("last time reset", last_reset_);
    stat.add("callback errors", errors_);
    if (errors_) stat.add("last callback error", last_error_);
    if (resets_ && (now - last_reset_time_).toSec() < warn_s_)
      stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, "time reset: " + last_reset_);
    if (errors_ && (now - last_error_time_).toSec() < warn_s_)
      stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, "callback error: " + last_error_);
  }

 private:
  double warn_s_;
  mutable std::mutex mutex_;
  std::uint64_t errors_ = 0, resets_ = 0;
  std::string last_error_, last_reset_;
  ros::WallTime last_error_time_, last_reset_time_;
};

/// ROS time as a clock for time-reset checks: set only under sim time once a
/// clock has arrived (0 otherwise: nothing to check).
inline std::int64_t simClockNs() {
  if (!ros::Time::isSimTime()) return 0;
  const ros::Time now = ros::Time::now();
  return now.isZero() ? 0 : std::int64_t(now.toNSec());
}

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_STAGE_HEALTH_H_
