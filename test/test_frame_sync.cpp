// FrameSetSync: exact and approximate grouping of any number of cameras, drops counted.
#include <gtest/gtest.h>

#include <string>

#include "fisheye_mapping/core/sync/frame_sync.h"

using namespace fisheye_mapping;

TEST(Sync, ExactTenCamerasInterleaved) {
  FrameSetSync<std::string> sync(10, SyncPolicy::Exact, 0.0, 8);
  int sets = 0;
  // Two frame times, cameras arriving interleaved and in reverse order.
  for (int cam = 9; cam >= 0; --cam) {
    for (std::int64_t t : {1000, 2000}) {
      auto out = sync.add(cam, t, "c" + std::to_string(cam) + "@" + std::to_string(t));
      if (!out.empty()) {
        ++sets;
        ASSERT_EQ(out[0].size(), 10u);
        for (int c = 0; c < 10; ++c) EXPECT_EQ(out[0][c].substr(0, out[0][c].find('@')), "c" + std::to_string(c));
        EXPECT_EQ(out[0][0], "c0@" + std::to_string(sets == 1 ? 1000 : 2000));
      }
    }
  }
  EXPECT_EQ(sets, 2);
  EXPECT_EQ(sync.stats().complete, 2u);
  EXPECT_EQ(sync.stats().dropped_incomplete, 0u);
}

TEST(Sync, ExactDropsIncompleteSetsWhenALaterOneCompletes) {
  FrameSetSync<int> sync(3, SyncPolicy::Exact, 0.0, 8);
  sync.add(0, 100, 0);
  sync.add(1, 100, 1);  // cam2's image of t=100 is lost
  EXPECT_TRUE(sync.add(0, 200, 0).empty());
  EXPECT_TRUE(sync.add(1, 200, 1).empty());
  EXPECT_EQ(sync.add(2, 200, 2).size(), 1u);
  EXPECT_EQ(sync.stats().dropped_incomplete, 1u);
  EXPECT_EQ(sync.open(), 0u);
  // A straggler for t=100 arrives: out of order, dropped.
  EXPECT_TRUE(sync.add(2, 100, 2).empty());
  EXPECT_EQ(sync.stats().dropped_out_of_order, 1u);
  // Jittered stamps never match exactly.
  sync.add(0, 300, 0);
  sync.add(1, 301, 1);
  EXPECT_TRUE(sync.add(2, 300, 2).empty());
}

TEST(Sync, ApproximateWithinMaxInterval) {
  FrameSetSync<int> sync(3, SyncPolicy::Approximate, 0.002, 8);  // 2 ms
  const std::int64_t ms = 1000000;
  sync.add(0, 100 * ms, 0);
  sync.add(1, 101 * ms, 1);
  auto out = sync.add(2, 99 * ms, 2);  // within 2 ms of the set's first stamp
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0], (std::vector<int>{0, 1, 2}));
  // 3 ms away: a new set, which never completes once the next one does.
  sync.add(0, 200 * ms, 0);
  sync.add(1, 203 * ms, 1);
  sync.add(2, 200 * ms, 2);
  sync.add(0, 300 * ms, 0);
  sync.add(1, 300 * ms, 1);
  out = sync.add(2, 301 * ms, 2);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(sync.stats().complete, 2u);
  EXPECT_EQ(sync.stats().dropped_incomplete, 2u);  // {cam0, cam2 @200} and {cam1 @203}
}

TEST(Sync, QueueBoundsOpenSetsAndBadArguments) {
  FrameSetSync<int> sync(2, SyncPolicy::Exact, 0.0, 3);
  for (int t = 1; t <= 5; ++t) sync.add(0, t, 0);  // camera 1 silent
  EXPECT_EQ(sync.open(), 3u);
  EXPECT_EQ(sync.stats().dropped_incomplete, 2u);
  EXPECT_THROW(sync.add(2, 1, 0), std::out_of_range);
  EXPECT_THROW(FrameSetSync<int>(0, SyncPolicy::Exact, 0, 1), std::invalid_argument);
  EXPECT_THROW(parseSyncPolicy("nearest"), std::invalid_argument);
}

// ---------------------------------------------------------------------------
// Time going backwards (a bag played twice, a player restarted, a clock reset).

namespace {
constexpr std::int64_t kS = 1000000000;  // ns per second
std::int64_t sec(double s) { return std::int64_t(s * 1e9 + 0.5); }

// One frame set at `t` (cameras 0..n-1 in order); returns the sets completed.
std::size_t feed(FrameSetSync<int>& sync, int n, double t) {
  std::size_t sets = 0;
  for (int c = 0; c < n; ++c) sets += sync.add(c, sec(t), c).size();
  return sets;
}
}  // namespace

TEST(FrameSyncTimeReset, BackwardsBeyondThresholdResetsAndNextSetsComplete) {
  FrameSetSync<int> sync(3, SyncPolicy::Exact, 0.0, 8, 1.0);
  for (double t : {100.0, 100.1, 100.2}) EXPECT_EQ(feed(sync, 3, t), 1u);
  sync.add(0, sec(100.3), 0);  // an open set the reset will drop
  // The bag starts again at 90 s: cam1 first.
  EXPECT_TRUE(sync.add(1, sec(90.0), 1).empty());
  EXPECT_EQ(sync.stats().time_resets, 1u);
  ASSERT_TRUE(sync.lastTimeReset());
  EXPECT_EQ(sync.lastTimeReset()->from_ns, sec(100.2));
  EXPECT_EQ(sync.lastTimeReset()->to_ns, sec(90.0));
  const std::string& why = sync.lastTimeReset()->reason;
  EXPECT_NE(why.find("time went backwards"), std::string::npos) << why;
  EXPECT_NE(why.find("100.200"), std::string::npos) << why;
  EXPECT_NE(why.find("90.000"), std::string::npos) << why;
  EXPECT_NE(why.find("camera 1"), std::string::npos) << why;
  EXPECT_NE(why.find("1 open set(s) dropped"), std::string::npos) << why;
  EXPECT_EQ(sync.stats().dropped_incomplete, 1u);
  EXPECT_EQ(sync.add(0, sec(90.0), 0).size(), 0u);
  EXPECT_EQ(sync.add(2, sec(90.0), 2).size(), 1u);  // the first set of the second play
  for (double t : {90.1, 90.2, 90.3}) EXPECT_EQ(feed(sync, 3, t), 1u);
  EXPECT_EQ(sync.stats().complete, 7u);
  EXPECT_EQ(sync.stats().time_resets, 1u);
  EXPECT_EQ(sync.stats().dropped_out_of_order, 0u);
  EXPECT_EQ(sync.stats().dropped_stale, 0u);
}

TEST(FrameSyncTimeReset, JitterWithinThresholdIsDroppedWithoutReset) {
  FrameSetSync<int> sync(3, SyncPolicy::Exact, 0.0, 8, 1.0);
  for (double t : {100.0, 100.1, 100.2}) EXPECT_EQ(feed(sync, 3, t), 1u);
  // 0.3 s and 0.9 s back: late images, not a new timeline.
  EXPECT_TRUE(sync.add(0, sec(99.9), 0).empty());
  EXPECT_TRUE(sync.add(2, sec(99.3), 2).empty());
  EXPECT_EQ(sync.stats().dropped_out_of_order, 2u);
  EXPECT_EQ(sync.stats().time_resets, 0u);
  EXPECT_FALSE(sync.lastTimeReset());
  EXPECT_EQ(feed(sync, 3, 100.3), 1u);
  EXPECT_EQ(sync.stats().complete, 4u);
}

TEST(FrameSyncTimeReset, ApproximatePolicyResetsToo) {
  FrameSetSync<int> sync(2, SyncPolicy::Approximate, 0.005, 8, 1.0);
  for (double t : {50.0, 50.1}) {
    sync.add(0, sec(t), 0);
    EXPECT_EQ(sync.add(1, sec(t) + 2000000, 1).size(), 1u);  // 2 ms apart
  }
  sync.add(0, sec(10.0), 0);
  EXPECT_EQ(sync.stats().time_resets, 1u);
  EXPECT_EQ(sync.add(1, sec(10.0) - 1000000, 1).size(), 1u);
}

TEST(FrameSyncTimeReset, OldTimelineStragglersAreDroppedAsStale) {
  FrameSetSync<int> sync(3, SyncPolicy::Exact, 0.0, 8, 1.0);
  for (double t : {100.0, 100.1}) EXPECT_EQ(feed(sync, 3, t), 1u);
  sync.add(0, sec(100.2), 0);
  sync.add(0, sec(90.0), 0);  // reset by cam0
  EXPECT_EQ(sync.stats().time_resets, 1u);
  // cam1's and cam2's 100.2 images were still in flight: stale, no second reset.
  EXPECT_TRUE(sync.add(1, sec(100.2), 1).empty());
  EXPECT_TRUE(sync.add(2, sec(100.2), 2).empty());
  EXPECT_EQ(sync.stats().dropped_stale, 2u);
  EXPECT_EQ(sync.add(1, sec(90.0), 1).size(), 0u);
  EXPECT_EQ(sync.add(2, sec(90.0), 2).size(), 1u);
  EXPECT_EQ(feed(sync, 3, 90.1), 1u);
  EXPECT_EQ(sync.stats().time_resets, 1u);
}

TEST(FrameSyncTimeReset, ClockJumpingBackResets) {
  FrameSetSync<int> sync(2, SyncPolicy::Exact, 0.0, 8, 1.0);
  for (double t : {100.0, 100.1}) EXPECT_EQ(feed(sync, 2, t), 1u);
  EXPECT_FALSE(sync.clockAt(sec(100.1)));
  EXPECT_FALSE(sync.clockAt(sec(99.5)));  // within the threshold
  sync.add(0, sec(100.2), 0);
  const auto r = sync.clockAt(sec(20.0));
  ASSERT_TRUE(r);
  EXPECT_EQ(r->from_ns, sec(100.2));
  EXPECT_EQ(r->to_ns, sec(20.0));
  EXPECT_NE(r->reason.find("clock jumped backwards"), std::string::npos) << r->reason;
  EXPECT_EQ(sync.stats().time_resets, 1u);
  EXPECT_EQ(sync.open(), 0u);
  EXPECT_FALSE(sync.clockAt(sec(20.0)));  // once
  // The new timeline may begin later than the clock at the reset (a bag whose
  // first images come seconds after its start): they are not stale.
  EXPECT_EQ(feed(sync, 2, 25.0), 1u);
  EXPECT_EQ(feed(sync, 2, 25.1), 1u);
  EXPECT_EQ(sync.stats().dropped_stale, 0u);
}

TEST(FrameSyncTimeReset, DisabledThresholdKeepsTheOldBehaviour) {
  FrameSetSync<int> sync(2, SyncPolicy::Exact, 0.0, 8, 0.0);
  EXPECT_EQ(feed(sync, 2, 100.0), 1u);
  EXPECT_EQ(feed(sync, 2, 10.0), 0u);
  EXPECT_EQ(sync.stats().dropped_out_of_order, 2u);
  EXPECT_EQ(sync.stats().time_resets, 0u);
  EXPECT_FALSE(sync.clockAt(sec(1.0)));
}

TEST(FrameSyncTimeReset, ManualResetForgetsStampsAndOpenSets) {
  FrameSetSync<int> sync(2, SyncPolicy::Exact, 0.0, 8);
  EXPECT_EQ(feed(sync, 2, 100.0), 1u);
  sync.add(0, sec(100.1), 0);
  sync.reset();
  EXPECT_EQ(sync.open(), 0u);
  EXPECT_EQ(sync.stats().dropped_incomplete, 1u);
  EXPECT_EQ(feed(sync, 2, 99.5), 1u);  // older than the last set, but forgotten
  EXPECT_EQ(sync.stats().time_resets, 0u);
}

TEST(StreamTimeline, TwoStreamsOneResetStragglersThenJoin) {
  // Detections (stream 1) run ahead of depth (stream 0): detections reset the
  // timeline first; the depth maps of the old play still in flight are stale,
  // then depth joins without a second reset.
  StreamTimeline tl(2, 1.0);
  using K = StreamTimeline::Kind;
  for (double t : {100.0, 100.1, 100.2}) {
    EXPECT_EQ(tl.observe(0, sec(t)).kind, K::kOk);
    EXPECT_EQ(tl.observe(1, sec(t)).kind, K::kOk);
  }
  EXPECT_EQ(tl.observe(1, sec(100.3)).kind, K::kOk);
  const auto r = tl.observe(1, sec(90.0));
  EXPECT_EQ(r.kind, K::kReset);
  EXPECT_EQ(r.from_ns, sec(100.3));
  EXPECT_EQ(r.to_ns, sec(90.0));
  EXPECT_EQ(tl.observe(0, sec(100.3)).kind, K::kStale);
  EXPECT_EQ(tl.observe(1, sec(90.1)).kind, K::kOk);
  EXPECT_EQ(tl.observe(0, sec(90.0)).kind, K::kJoined);
  EXPECT_EQ(tl.observe(0, sec(90.1)).kind, K::kOk);
  EXPECT_EQ(tl.resets(), 1u);
  EXPECT_EQ(tl.stale(), 1u);
  // A second play of the same stamps is a new reset, not a join.
  EXPECT_EQ(tl.observe(0, sec(88.0)).kind, K::kReset);
  EXPECT_EQ(tl.resets(), 2u);
}

TEST(StreamTimeline, AStreamThatStaysAheadJoinsInsteadOfStallingAndSmallStepsAreOk) {
  StreamTimeline tl(2, 1.0);
  using K = StreamTimeline::Kind;
  tl.observe(0, 100 * kS);
  tl.observe(1, 100 * kS);
  EXPECT_EQ(tl.observe(0, 50 * kS).kind, K::kReset);  // one glitched stamp on stream 0
  // Stream 1 goes on at 100 s and beyond: stale at first, then no longer
  // believed to be a straggler (more than 3 thresholds of its own time).
  EXPECT_EQ(tl.observe(1, 101 * kS).kind, K::kStale);
  EXPECT_EQ(tl.observe(1, 103 * kS).kind, K::kStale);
  EXPECT_EQ(tl.observe(1, sec(104.5)).kind, K::kJoined);
  EXPECT_EQ(tl.observe(1, 105 * kS).kind, K::kOk);
  // Within the threshold: no reset.
  EXPECT_EQ(tl.observe(1, sec(104.2)).kind, K::kOk);
  EXPECT_THROW(tl.observe(2, 0), std::out_of_range);
  EXPECT_THROW(StreamTimeline(0, 1.0), std::invalid_argument);
}

// ---------------------------------------------------------------------------
// Every frame set accounted for: complete + dropped by reason = the sets fed.

TEST(FrameSyncAccounting, StampsBackwardsCountedOncePerFrameSet) {
  FrameSetSync<int> sync(3, SyncPolicy::Exact, 0.0, 8, 1.0);
  // Ten frame sets; the last five step back 50 ms between the first five's
  // stamps (small steps: late images, not a new timeline).
  const double stamps[] = {1.0, 1.1, 1.2, 1.3, 1.4, 1.05, 1.15, 1.25, 1.35, 1.45};
  std::size_t published = 0;
  for (double t : stamps) published += feed(sync, 3, t);
  sync.finish();
  const auto& s = sync.stats();
  EXPECT_EQ(published, 6u);
  EXPECT_EQ(s.complete, 6u);
  EXPECT_EQ(s.sets_backwards, 4u);  // 1.05 .. 1.35: three images each, one frame set each
  EXPECT_EQ(s.dropped_out_of_order, 12u);
  EXPECT_EQ(s.sets_duplicate, 0u);
  EXPECT_EQ(s.dropped_incomplete, 0u);
  EXPECT_EQ(s.sets(), 10u);
  EXPECT_EQ(s.time_resets, 0u);
}

TEST(FrameSyncAccounting, AllImagesSharingOneStampAreDuplicates) {
  FrameSetSync<int> sync(2, SyncPolicy::Exact, 0.0, 8, 1.0);
  std::size_t published = 0;
  for (int k = 0; k < 10; ++k) published += feed(sync, 2, 5.0);
  sync.finish();
  const auto& s = sync.stats();
  EXPECT_EQ(published, 1u);
  EXPECT_EQ(s.sets_duplicate, 9u);
  EXPECT_EQ(s.sets_backwards, 0u);
  EXPECT_EQ(s.dropped_incomplete, 0u);
  EXPECT_EQ(s.sets(), 10u);
}

TEST(FrameSyncAccounting, DuplicateWhileOpenIsCountedNotLost) {
  // cam0 sends its 2.0 image twice before cam1's arrives: the second copy was
  // once an open set that vanished uncounted when the first completed.
  FrameSetSync<int> sync(2, SyncPolicy::Exact, 0.0, 8, 1.0);
  sync.add(0, sec(2.0), 0);
  sync.add(0, sec(2.0), 0);
  EXPECT_EQ(sync.open(), 1u);
  EXPECT_EQ(sync.add(1, sec(2.0), 1).size(), 1u);
  EXPECT_EQ(sync.stats().sets_duplicate, 1u);
  EXPECT_EQ(sync.stats().sets(), 2u);
}

TEST(FrameSyncAccounting, LateImageOfAnIncompleteSetAndOpenSetsAtTheEnd) {
  FrameSetSync<int> sync(3, SyncPolicy::Exact, 0.0, 8, 1.0);
  sync.add(0, sec(1.0), 0);
  sync.add(1, sec(1.0), 1);
  EXPECT_EQ(feed(sync, 3, 1.1), 1u);  // 1.0 dropped as incomplete
  sync.add(2, sec(1.0), 2);           // its late image: the same frame set, not another
  sync.add(0, sec(1.2), 0);           // open at the end of the stream
  sync.finish();
  const auto& s = sync.stats();
  EXPECT_EQ(s.complete, 1u);
  EXPECT_EQ(s.dropped_incomplete, 2u);
  EXPECT_EQ(s.dropped_out_of_order, 1u);
  EXPECT_EQ(s.sets_backwards, 0u);
  EXPECT_EQ(s.sets(), 3u);
  EXPECT_EQ(sync.open(), 0u);
}

TEST(FrameSyncAccounting, OldTimelineStragglersJoinTheSetTheResetDropped) {
  FrameSetSync<int> sync(3, SyncPolicy::Exact, 0.0, 8, 1.0);
  for (double t : {100.0, 100.1}) EXPECT_EQ(feed(sync, 3, t), 1u);
  sync.add(0, sec(100.2), 0);
  sync.add(0, sec(90.0), 0);  // reset: {cam0 @100.2} dropped as incomplete
  sync.add(1, sec(100.2), 1);
  sync.add(2, sec(100.2), 2);
  sync.add(1, sec(90.0), 1);
  EXPECT_EQ(sync.add(2, sec(90.0), 2).size(), 1u);
  sync.finish();
  const auto& s = sync.stats();
  EXPECT_EQ(s.dropped_stale, 2u);
  EXPECT_EQ(s.sets_stale, 0u);  // the same frame set as the incomplete one
  EXPECT_EQ(s.dropped_incomplete, 1u);
  EXPECT_EQ(s.sets(), 4u);  // 100.0, 100.1, 100.2, 90.0
}

TEST(FrameSyncAccounting, ApproximatePolicyAddsUp) {
  FrameSetSync<int> sync(2, SyncPolicy::Approximate, 0.005, 8, 1.0);
  const std::int64_t ms = 1000000;
  for (int k = 0; k < 5; ++k) {
    sync.add(0, sec(1.0 + 0.1 * k), 0);
    sync.add(1, sec(1.0 + 0.1 * k) + 2 * ms, 1);
  }
  sync.add(0, sec(1.15), 0);  // backwards
  sync.add(1, sec(1.15) + 1 * ms, 1);
  sync.add(1, sec(1.4) + 2 * ms, 1);  // duplicate of cam1's last
  sync.finish();
  const auto& s = sync.stats();
  EXPECT_EQ(s.complete, 5u);
  EXPECT_EQ(s.sets_backwards, 1u);
  EXPECT_EQ(s.sets_duplicate, 1u);
  EXPECT_EQ(s.sets(), 7u);
}
