// The sync stage's bookkeeping (core/sync/sync_report.h), against counts and
// times worked out by hand.
#include <map>

#include <gtest/gtest.h>

#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/core/sync/sync_report.h"

namespace fm = fisheye_mapping;

namespace {
fm::Rig rigOf(std::vector<std::string> rostopics) {
  fm::Rig rig;
  for (std::size_t i = 0; i < rostopics.size(); ++i) {
    fm::RigCamera c;
    c.name = "cam" + std::to_string(i);
    c.rostopic = rostopics[i];
    rig.cameras.push_back(c);
  }
  return rig;
}
}  // namespace

TEST(SyncReport, TopicsFromTheCamchainUnlessGiven) {
  EXPECT_EQ(fm::imageTopicsForRig(rigOf({"/a/image", "/b/image"}), {}),
            (std::vector<std::string>{"/a/image", "/b/image"}));
  EXPECT_EQ(fm::imageTopicsForRig(rigOf({"/a/image", ""}), {"/x", "/y"}), (std::vector<std::string>{"/x", "/y"}));
  try {
    fm::imageTopicsForRig(rigOf({"/a/image", ""}), {});
    FAIL() << "a camera without a rostopic was accepted";
  } catch (const fm::CalibrationError& e) {
    EXPECT_NE(std::string(e.what()).find("camera cam1 has no rostopic"), std::string::npos) << e.what();
  }
  try {
    fm::imageTopicsForRig(rigOf({"/a", "/b", "/c"}), {"/x", "/y"});
    FAIL() << "two topics for three cameras were accepted";
  } catch (const fm::CalibrationError& e) {
    EXPECT_NE(std::string(e.what()).find("2 topics for 3 cameras"), std::string::npos) << e.what();
  }
}

TEST(SyncReport, ImageSizeAgainstTheCalibration) {
  fm::Intrinsics in;
  in.width = 640;
  in.height = 480;
  in.fx = in.fy = 300;
  in.cx = 319.5;
  in.cy = 239.5;
  const fm::CameraModel cam = fm::CameraModel::pinhole(in);
  EXPECT_FALSE(fm::imageSizeMismatch(640, 480, "mono8", cam));
  const auto why = fm::imageSizeMismatch(320, 240, "mono8", cam);
  ASSERT_TRUE(why);
  EXPECT_EQ(*why, "image 320x240 mono8: the calibration says 640x480");
}

TEST(SyncReport, DropsByReasonFromTwoReadings) {
  using Stats = fm::FrameSetSync<int>::Stats;
  Stats before, now;
  before.dropped_incomplete = 1;
  now.dropped_incomplete = 3;
  now.dropped_out_of_order = 1;
  now.dropped_stale = 0;
  EXPECT_EQ(fm::newSyncDrops(before, now),
            (std::vector<std::string>{"incomplete set", "incomplete set", "out-of-order image"}));
  EXPECT_TRUE(fm::newSyncDrops(now, now).empty());
}

TEST(SyncReport, ValuesOfARealSync) {
  // Two cameras, exact policy, queue 1: t=1 complete; t=2 from cam0 only is
  // pushed out by t=3 (incomplete); t=3 complete; cam1 at t=1 again: out of order.
  fm::FrameSetSync<int> sync(2, fm::SyncPolicy::Exact, 0.0, 1, 0.0);
  const std::int64_t s = 1000000000;
  sync.add(0, 1 * s, 10);
  sync.add(1, 1 * s, 11);
  sync.add(0, 2 * s, 20);
  sync.add(0, 3 * s, 30);
  sync.add(1, 3 * s, 31);
  sync.add(1, 1 * s, 12);
  std::map<std::string, std::uint64_t> v;
  for (const auto& kv : fm::syncReportValues(sync.stats())) v[kv.first] = kv.second;
  EXPECT_EQ(v["frame sets out"], 2u);
  EXPECT_EQ(v["frame sets dropped: incomplete"], 1u);
  EXPECT_EQ(v["frame sets dropped"], v["frame sets dropped: incomplete"] + v["frame sets dropped: stamps backwards"] +
                                         v["frame sets dropped: duplicate stamp"] + v["frame sets dropped: old timeline"]);
  EXPECT_EQ(v["out-of-order images dropped"], 1u);
  EXPECT_EQ(fm::syncReportValues(sync.stats()).size(), 9u);
}

TEST(CameraActivity, SilenceSinceTheLastImageOrSinceListening) {
  fm::CameraActivity a(3, 10.0);
  a.listening(100.0);
  a.arrived(0, 101.0);
  a.arrived(1, 103.0);
  a.bad(1);
  // At 104.5 with 2 s: cam0 silent 3.5 s, cam1 1.5 s, cam2 (none) 4.5 s since listening.
  EXPECT_EQ(a.silent(104.5, 2.0), (std::vector<int>{0, 2}));
  EXPECT_EQ(a.received(1), 1u);
  EXPECT_EQ(a.badImages(1), 1u);
  EXPECT_EQ(a.badImages(0), 0u);
  // The clock went back to 50: every camera starts there; nobody is silent at 51.
  a.clockWentBack(50.0);
  EXPECT_TRUE(a.silent(51.0, 2.0).empty());
  EXPECT_EQ(a.silent(52.5, 2.0), (std::vector<int>{0, 1, 2}));
}

TEST(CameraActivity, NoClockYetWhenListeningBegan) {
  fm::CameraActivity a(1, 10.0);
  a.listening(0.0);  // sim time before /clock
  EXPECT_TRUE(a.silent(20.0, 2.0).empty());  // the clock is taken from here
  EXPECT_EQ(a.silent(22.5, 2.0), (std::vector<int>{0}));
}
