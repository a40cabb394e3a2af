// The nodelets' shared glue (ros/nodelet_glue.h) without a ROS master: a
// StageMonitor without ROS, callbacks that count what they were asked to do.
#include <stdexcept>

#include <gtest/gtest.h>
#include <ros/time.h>

#include "fisheye_mapping/ros/nodelet_glue.h"

namespace fm = fisheye_mapping;

namespace {
const std::int64_t kS = 1000000000;

std::uint64_t drops(fm::StageMonitor& m, const std::string& reason) {
  const auto s = m.stats().snapshot();
  const auto it = s.dropped.find(reason);
  return it == s.dropped.end() ? 0 : it->second.total;
}
}  // namespace

TEST(NodeletGlue, TimeResetAsTheDiagnosticsShowIt) {
  EXPECT_EQ(fm::describeTimeReset(140 * kS, 120 * kS, "why"), "140.000 s -> 120.000 s: why");
  EXPECT_EQ(fm::describeTimeReset(2 * kS + kS / 2, kS, "why", "depth"), "depth 2.500 s -> 1.000 s: why");
}

TEST(NodeletGlue, GuardedCountsTheErrorAndGoesOn) {
  ros::Time::init();
  fm::StageMonitor monitor("test");
  fm::NodeletLogger log("glue_test");
  int ran = 0;
  EXPECT_TRUE(fm::guarded(monitor, log, "depth", ros::Time(3, 0), [&] { ++ran; }));
  EXPECT_FALSE(fm::guarded(monitor, log, "depth", ros::Time(3, 0), [] { throw std::runtime_error("bad encoding"); }));
  EXPECT_FALSE(fm::guarded(monitor, log, "timer", ros::Time(4, 0), [] { throw 7; }));
  EXPECT_EQ(ran, 1);
  EXPECT_EQ(monitor.health().errors(), 2u);
  diagnostic_updater::DiagnosticStatusWrapper stat;
  monitor.fill(stat, fm::StageStats::now());
  std::string last;
  for (const auto& kv : stat.values)
    if (kv.key == "last callback error") last = kv.value;
  EXPECT_EQ(last, "timer at 4.000: unknown exception");
}

TEST(NodeletGlue, LazySubscriptionFollowsTheListeners) {
  fm::StageMonitor monitor("test");
  fm::NodeletLogger log("glue_test");
  bool listeners = false, fail = false;
  int subscribed = 0, unsubscribed = 0;
  fm::LazySubscription sub(
      monitor, log, "the frame sets", [&] { return listeners; },
      [&] {
        if (fail) throw std::runtime_error("no such transport");
        ++subscribed;
      },
      [&] { ++unsubscribed; });
  sub.update();
  EXPECT_FALSE(sub.active());
  EXPECT_EQ(subscribed + unsubscribed, 0);
  listeners = true;
  sub.update();
  sub.update();  // already subscribed: nothing more
  EXPECT_TRUE(sub.active());
  EXPECT_EQ(subscribed, 1);
  listeners = false;
  sub.update();
  EXPECT_FALSE(sub.active());
  EXPECT_EQ(unsubscribed, 1);
  // A subscription that throws is undone, counted, and tried again at the next update.
  listeners = fail = true;
  sub.update();
  EXPECT_FALSE(sub.active());
  EXPECT_EQ(unsubscribed, 2);
  EXPECT_EQ(monitor.health().errors(), 1u);
  fail = false;
  sub.update();
  EXPECT_TRUE(sub.active());
  EXPECT_EQ(subscribed, 2);
}

TEST(NodeletGlue, StageTimelineResetsDropsStragglersAndCounts) {
  fm::StageMonitor monitor("test");
  fm::NodeletLogger log("glue_test");
  std::vector<std::string> resets;
  fm::StageTimeline time(monitor, log, "depth mask", {"depth", "detections"}, 1.0,
                         [&](const fm::StreamTimeline::Event& ev, const std::string& stream) {
                           resets.push_back(stream + " " + fm::formatStamp(ev.from_ns) + " " + fm::formatStamp(ev.to_ns));
                           return std::string("pairing reset");
                         });
  EXPECT_TRUE(time.observe(0, ros::Time(100, 0)));
  EXPECT_TRUE(time.observe(1, ros::Time(100, 0)));
  EXPECT_TRUE(time.observe(0, ros::Time(99, 500000000)));  // 0.5 s back: within the threshold
  EXPECT_TRUE(resets.empty());
  EXPECT_TRUE(time.observe(0, ros::Time(50, 0)));  // 50 s back: a reset
  ASSERT_EQ(resets.size(), 1u);
  EXPECT_EQ(resets[0], "depth 100.000 50.000");
  EXPECT_EQ(monitor.health().resets(), 1u);
  // The detections still at 101 s belong to the old timeline: dropped as stale.
  EXPECT_FALSE(time.observe(1, ros::Time(101, 0)));
  EXPECT_EQ(drops(monitor, "stale (old timeline)"), 1u);
  EXPECT_TRUE(time.observe(1, ros::Time(50, 100000000)));  // joined the new timeline
  // The clock 10 s behind the newest stamp (50.1 s): a reset named "clock".
  time.clock(40 * kS, "clock");
  ASSERT_EQ(resets.size(), 2u);
  EXPECT_EQ(resets[1], "clock 50.100 40.000");
  time.clock(40 * kS, "clock");  // nothing new since
  EXPECT_EQ(resets.size(), 2u);
  // Threshold 0: never.
  time.setThreshold(0.0);
  EXPECT_TRUE(time.observe(0, ros::Time(10, 0)));
  EXPECT_TRUE(time.observe(0, ros::Time(1, 0)));
  EXPECT_EQ(resets.size(), 2u);
  EXPECT_EQ(monitor.health().resets(), 2u);
}
