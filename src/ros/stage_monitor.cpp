#include "fisheye_mapping/ros/stage_monitor.h"

#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "fisheye_mapping/ros/node_options.h"
#include "fisheye_mapping/ros/ros_params.h"

namespace fisheye_mapping {

namespace {

using diagnostic_msgs::DiagnosticStatus;
using diagnostic_updater::DiagnosticStatusWrapper;

std::string format(const char* fmt, double a, double b = 0, double c = 0) {
  char buf[96];
  std::snprintf(buf, sizeof buf, fmt, a, b, c);
  return buf;
}

// "<n> in the last <w> s, <total> total": what a count means at a glance.
std::string windowCount(const StageStatsSnapshot::Count& c, double window_s) {
  return std::to_string(c.window) + " in the last " + format("%g", window_s) + " s, " + std::to_string(c.total) +
         " total";
}

void addValues(DiagnosticStatusWrapper& stat, const StageStatsSnapshot& s) {
  stat.addf("input rate (Hz)", "%.2f", s.input.rate_hz);
  stat.addf("output rate (Hz)", "%.2f", s.output.rate_hz);
  stat.add("inputs", s.input.total);
  stat.add("outputs", s.output.total);
  stat.add("last input (s ago)", s.input.total ? format("%.1f", s.input.age_s) : std::string("never"));
  const auto& p = s.processing;
  stat.add("processing time last/mean/max (ms)",
           p.total ? format("%.1f / %.1f / %.1f", 1e3 * p.last_s, 1e3 * p.mean_s, 1e3 * p.max_s) : std::string("none"));
  for (const auto& [reason, count] : s.dropped) stat.add("dropped: " + reason, windowCount(count, s.window_s));
  stat.add("tf failures", windowCount(s.tf_failures, s.window_s));
  if (s.tf_failures.total) stat.add("last tf failure", s.last_tf_failure);
}

// "no pose 3, queue full 1": the reasons with drops in the window.
std::string recentDrops(const StageStatsSnapshot& s) {
  std::string list;
  for (const auto& [reason, count] : s.dropped)
    if (count.window) list += (list.empty() ? "" : ", ") + reason + " " + std::to_string(count.window);
  return list;
}

}  // namespace

StageMonitorOptions StageMonitorOptions::fromParams(const ParamSource& params) {
  return fromParams(params, StageMonitorOptions());
}

StageMonitorOptions StageMonitorOptions::fromParams(const ParamSource& params, StageMonitorOptions defaults) {
  // Declared once, with the other node options (DiagnosticOptions).
  DiagnosticOptions d;
  d.diagnostic_window = defaults.window_s;
  d.diagnostic_expected_period = defaults.expected_period_s;
  d = DiagnosticOptions::params().read(params, d);
  StageMonitorOptions o = defaults;
  o.window_s = d.diagnostic_window;
  o.expected_period_s = d.diagnostic_expected_period;
  return o;
}

StageMonitor::StageMonitor(std::string stage_name, Options options)
    : stage_(std::move(stage_name)), options_(Options::fromParams(MapParams(), options)), stats_(options_.window_s) {}

StageMonitor::StageMonitor(ros::NodeHandle nh, ros::NodeHandle pnh, std::string stage_name, Options defaults)
    : StageMonitor(std::move(stage_name), Options::fromParams(RosParams(pnh), defaults)) {
  // A nodelet's private namespace is its name, as getName() gives it.
  updater_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, pnh.getNamespace());
  const DiagnosticOptions d = DiagnosticOptions::params().read(RosParams(pnh), DiagnosticOptions());
  updater_->setHardwareID(d.hardware_id.empty() ? pnh.getNamespace() : d.hardware_id);
  updater_->add(stage_, this, &StageMonitor::report);
  period_s_ = updater_->getPeriod();
  timer_ = nh.createWallTimer(ros::WallDuration(period_s_), [this](const ros::WallTimerEvent&) { publish(); });
}

StageMonitor::~StageMonitor() { timer_.stop(); }

void StageMonitor::setExtraReport(ExtraReport report) {
  std::lock_guard<std::mutex> l(extra_mutex_);
  extra_ = std::move(report);
}

void StageMonitor::publish() {
  try {
    updater_->force_update();
    // force_update() rereads ~diagnostic_period; follow a change.
    const double period = updater_->getPeriod();
    if (period > 0 && period != period_s_) timer_.setPeriod(ros::WallDuration(period_s_ = period));
  } catch (const std::exception& e) {
    health_.error(std::string("diagnostics: ") + e.what());
    ROS_ERROR_THROTTLE(10.0, "%s: diagnostics not published: %s", stage_.c_str(), e.what());
  }
}

void StageMonitor::report(DiagnosticStatusWrapper& stat) {
  try {
    fill(stat, StageStats::now());
  } catch (const std::exception& e) {  // e.g. from the stage's extra report
    stat.summary(DiagnosticStatus::ERROR, std::string("diagnostics failed: ") + e.what());
  }
}

// WARN for each cause, named in the message.
void StageMonitor::warn(DiagnosticStatusWrapper& stat, const StageStatsSnapshot& s) const {
  const double period = options_.expected_period_s;
  if (input_expected_ && s.input.total && s.input.age_s > kStallPeriods * period)
    stat.mergeSummary(DiagnosticStatus::WARN,
                      format("stalled: no input for %.1f s (expected every %g s)", s.input.age_s, period));
  const std::string within = format(" in the last %g s", s.window_s);
  if (s.dropped_all.window) stat.mergeSummary(DiagnosticStatus::WARN, "dropped" + within + ": " + recentDrops(s));
  if (s.tf_failures.window)
    stat.mergeSummary(DiagnosticStatus::WARN, "tf lookups failed" + within + ": " +
                                                  std::to_string(s.tf_failures.window) + " (last: " +
                                                  s.last_tf_failure + ")");
}

void StageMonitor::fill(DiagnosticStatusWrapper& stat, double now) const {
  const StageStatsSnapshot s = stats_.snapshot(now);
  stat.summary(DiagnosticStatus::OK, s.input.total ? "running" : "waiting for input");
  addValues(stat, s);
  warn(stat, s);
  health_.report(stat);
  ExtraReport extra;
  {
    std::lock_guard<std::mutex> l(extra_mutex_);
    extra = extra_;
  }
  if (extra) extra(stat);
}

}  // namespace fisheye_mapping
