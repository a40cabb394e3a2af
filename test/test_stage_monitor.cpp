// StageMonitor (ros/stage_monitor.h) without a ROS master: fill() on a
// DiagnosticStatusWrapper at chosen steady-clock times, its values and its
// summaries against hand-computed figures.
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

#include "fisheye_mapping/ros/stage_monitor.h"

using diagnostic_msgs::DiagnosticStatus;
using diagnostic_updater::DiagnosticStatusWrapper;
using fisheye_mapping::MapParams;
using fisheye_mapping::StageMonitor;

namespace {

DiagnosticStatusWrapper fillAt(const StageMonitor& m, double now) {
  DiagnosticStatusWrapper stat;
  m.fill(stat, now);
  return stat;
}

// The value of `key`, or "<missing>".
std::string value(const DiagnosticStatusWrapper& stat, const std::string& key) {
  for (const auto& kv : stat.values)
    if (kv.key == key) return kv.value;
  return "<missing>";
}

bool hasKeyStartingWith(const DiagnosticStatusWrapper& stat, const std::string& prefix) {
  for (const auto& kv : stat.values)
    if (kv.key.rfind(prefix, 0) == 0) return true;
  return false;
}

// A 2 Hz stream from 0 to 10 s: each input processed in 10 ms (even items) or
// 30 ms (odd ones) and published 0.1 s later.
void feedTwoHz(StageMonitor& m) {
  for (int i = 0; i <= 20; ++i) {
    const double t = 0.5 * i;
    m.stats().input(t);
    m.stats().processed(i % 2 ? 0.030 : 0.010, t);
    m.stats().output(t + 0.1);
  }
}

}  // namespace

TEST(StageMonitor, BeforeAnyInput) {
  StageMonitor m("depth");
  const auto stat = fillAt(m, 100.0);
  EXPECT_EQ(stat.level, DiagnosticStatus::OK);
  EXPECT_EQ(stat.message, "waiting for input");
  EXPECT_EQ(value(stat, "input rate (Hz)"), "0.00");
  EXPECT_EQ(value(stat, "output rate (Hz)"), "0.00");
  EXPECT_EQ(value(stat, "inputs"), "0");
  EXPECT_EQ(value(stat, "outputs"), "0");
  EXPECT_EQ(value(stat, "last input (s ago)"), "never");
  EXPECT_EQ(value(stat, "processing time last/mean/max (ms)"), "none");
  EXPECT_EQ(value(stat, "tf failures"), "0 in the last 10 s, 0 total");
  EXPECT_EQ(value(stat, "last tf failure"), "<missing>");
  EXPECT_FALSE(hasKeyStartingWith(stat, "dropped: "));
  // StageHealth's values come along.
  EXPECT_EQ(value(stat, "time resets"), "0");
  EXPECT_EQ(value(stat, "callback errors"), "0");
}

TEST(StageMonitor, SteadyStreamValues) {
  StageMonitor m("depth");
  feedTwoHz(m);
  // At 10.2 s: window [0.2, 10.2] holds inputs 0.5 .. 10 (20 of them, 10 of
  // 10 ms and 10 of 30 ms) and outputs 0.6 .. 10.1.
  const auto stat = fillAt(m, 10.2);
  EXPECT_EQ(stat.level, DiagnosticStatus::OK);
  EXPECT_EQ(stat.message, "running");
  EXPECT_EQ(value(stat, "input rate (Hz)"), "2.00");
  EXPECT_EQ(value(stat, "output rate (Hz)"), "2.00");
  EXPECT_EQ(value(stat, "inputs"), "21");
  EXPECT_EQ(value(stat, "outputs"), "21");
  EXPECT_EQ(value(stat, "last input (s ago)"), "0.2");
  EXPECT_EQ(value(stat, "processing time last/mean/max (ms)"), "10.0 / 20.0 / 30.0");
}

TEST(StageMonitor, StalledInputWarns) {
  StageMonitor m("depth");  // expected every 1 s: stalled after 3 s
  feedTwoHz(m);             // last input at 10 s
  auto stat = fillAt(m, 12.9);
  EXPECT_EQ(stat.level, DiagnosticStatus::OK) << stat.message;
  stat = fillAt(m, 13.5);
  EXPECT_EQ(stat.level, DiagnosticStatus::WARN);
  EXPECT_EQ(stat.message, "stalled: no input for 3.5 s (expected every 1 s)");
  EXPECT_EQ(value(stat, "last input (s ago)"), "3.5");
  EXPECT_EQ(value(stat, "input rate (Hz)"), "1.40");  // 3.5 .. 10: min(13 / 6.5, 14 / 10)

  // Not while the stage expects no input.
  m.setInputExpected(false);
  EXPECT_EQ(fillAt(m, 13.5).level, DiagnosticStatus::OK);
  m.setInputExpected(true);
  EXPECT_EQ(fillAt(m, 13.5).level, DiagnosticStatus::WARN);
}

TEST(StageMonitor, ExpectedPeriodIsConfigurable) {
  StageMonitor::Options o;
  o.expected_period_s = 0.5;  // stalled after 1.5 s
  StageMonitor m("detector", o);
  feedTwoHz(m);
  EXPECT_EQ(fillAt(m, 11.4).level, DiagnosticStatus::OK);
  const auto stat = fillAt(m, 11.6);
  EXPECT_EQ(stat.level, DiagnosticStatus::WARN);
  EXPECT_EQ(stat.message, "stalled: no input for 1.6 s (expected every 0.5 s)");
}

TEST(StageMonitor, DropsWarnWhileInTheWindow) {
  StageMonitor m("tsdf");
  m.stats().input(6.5);
  m.stats().dropped("no pose", 5.0);
  m.stats().dropped("queue full", 6.0);
  m.stats().dropped("no pose", 7.0);
  auto stat = fillAt(m, 8.0);
  EXPECT_EQ(stat.level, DiagnosticStatus::WARN);
  EXPECT_EQ(stat.message, "dropped in the last 10 s: no pose 2, queue full 1");
  EXPECT_EQ(value(stat, "dropped: no pose"), "2 in the last 10 s, 2 total");
  EXPECT_EQ(value(stat, "dropped: queue full"), "1 in the last 10 s, 1 total");
  // Window [6.5, 16.5]: one "no pose" left; input stalled too (10 s).
  stat = fillAt(m, 16.5);
  EXPECT_EQ(stat.message,
            "stalled: no input for 10.0 s (expected every 1 s); dropped in the last 10 s: no pose 1");
  // Once out of the window, only the totals remain.
  m.setInputExpected(false);
  stat = fillAt(m, 20.0);
  EXPECT_EQ(stat.level, DiagnosticStatus::OK) << stat.message;
  EXPECT_EQ(value(stat, "dropped: no pose"), "0 in the last 10 s, 2 total");
}

TEST(StageMonitor, TfFailuresWarnWhileInTheWindow) {
  StageMonitor m("depth");
  m.stats().tfFailure("map -> base_link at 3.000: extrapolation into the future", 3.0);
  auto stat = fillAt(m, 4.0);
  EXPECT_EQ(stat.level, DiagnosticStatus::WARN);
  EXPECT_EQ(stat.message,
            "tf lookups failed in the last 10 s: 1 (last: map -> base_link at 3.000: extrapolation into the future)");
  EXPECT_EQ(value(stat, "tf failures"), "1 in the last 10 s, 1 total");
  EXPECT_EQ(value(stat, "last tf failure"), "map -> base_link at 3.000: extrapolation into the future");
  stat = fillAt(m, 14.0);
  EXPECT_EQ(stat.level, DiagnosticStatus::OK);
  EXPECT_EQ(value(stat, "tf failures"), "0 in the last 10 s, 1 total");
}

TEST(StageMonitor, HealthWarnsThroughTheMonitor) {
  StageMonitor m("mask");
  m.error("depth at 3.000: bad encoding");
  m.timeReset("5.000 s -> 1.000 s: bag restarted");
  const auto stat = fillAt(m, 1.0);
  EXPECT_EQ(stat.level, DiagnosticStatus::WARN);
  EXPECT_EQ(stat.message,
            "time reset: 5.000 s -> 1.000 s: bag restarted; callback error: depth at 3.000: bad encoding");
  EXPECT_EQ(value(stat, "callback errors"), "1");
  EXPECT_EQ(value(stat, "last callback error"), "depth at 3.000: bad encoding");
  EXPECT_EQ(value(stat, "time resets"), "1");
  EXPECT_EQ(m.health().errors(), 1u);
}

TEST(StageMonitor, ExtraReportComesLast) {
  StageMonitor m("tsdf");
  m.setExtraReport([](DiagnosticStatusWrapper& stat) {
    stat.add("allocated blocks", 1234);
    stat.mergeSummary(DiagnosticStatus::WARN, "map memory above 80 %");
  });
  const auto stat = fillAt(m, 1.0);
  ASSERT_FALSE(stat.values.empty());
  EXPECT_EQ(stat.values.back().key, "allocated blocks");
  EXPECT_EQ(stat.values.back().value, "1234");
  EXPECT_EQ(stat.level, DiagnosticStatus::WARN);
  EXPECT_EQ(stat.message, "map memory above 80 %");
}

TEST(StageMonitor, WindowOptionAndParameters) {
  MapParams p;
  p.set("diagnostic_window", 5.0);
  p.set("diagnostic_expected_period", 0.2);
  const auto o = StageMonitor::Options::fromParams(p);
  EXPECT_EQ(o.window_s, 5.0);
  EXPECT_EQ(o.expected_period_s, 0.2);
  StageMonitor m("sync", o);
  EXPECT_EQ(m.stats().windowSeconds(), 5.0);
  m.stats().dropped("incomplete set", 1.0);
  EXPECT_EQ(value(fillAt(m, 2.0), "dropped: incomplete set"), "1 in the last 5 s, 1 total");
  EXPECT_EQ(m.updater(), nullptr);
  EXPECT_EQ(m.stageName(), "sync");

  // Absent parameters keep the defaults given.
  StageMonitor::Options d;
  d.expected_period_s = 2.0;
  EXPECT_EQ(StageMonitor::Options::fromParams(MapParams(), d).expected_period_s, 2.0);
  EXPECT_EQ(StageMonitor::Options::fromParams(MapParams(), d).window_s, 10.0);
}

TEST(StageMonitor, RejectsBadParameters) {
  MapParams p;
  p.set("diagnostic_expected_period", -1.0);
  try {
    StageMonitor::Options::fromParams(p);
    ADD_FAILURE() << "negative period accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("diagnostic_expected_period"), std::string::npos) << e.what();
  }
  MapParams q;
  q.set("diagnostic_window", "ten");
  EXPECT_THROW(StageMonitor::Options::fromParams(q), std::invalid_argument);
  StageMonitor::Options o;
  o.window_s = 0;
  EXPECT_THROW(StageMonitor("depth", o), std::invalid_argument);
}
