// FrameSetSync: exact and approximate grouping of any number of cameras, drops counted.
#include <gtest/gtest.h>

#include <string>

#include "fisheye_mapping/core/frame_sync.h"

using namespace fisheye_mapping;

TEST(FrameSync, ExactTenCamerasInterleaved) {
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

TEST(FrameSync, ExactDropsIncompleteSetsWhenALaterOneCompletes) {
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

TEST(FrameSync, ApproximateWithinMaxInterval) {
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

TEST(FrameSync, QueueBoundsOpenSetsAndBadArguments) {
  FrameSetSync<int> sync(2, SyncPolicy::Exact, 0.0, 3);
  for (int t = 1; t <= 5; ++t) sync.add(0, t, 0);  // camera 1 silent
  EXPECT_EQ(sync.open(), 3u);
  EXPECT_EQ(sync.stats().dropped_incomplete, 2u);
  EXPECT_THROW(sync.add(2, 1, 0), std::out_of_range);
  EXPECT_THROW(FrameSetSync<int>(0, SyncPolicy::Exact, 0, 1), std::invalid_argument);
  EXPECT_THROW(parseSyncPolicy("nearest"), std::invalid_argument);
}
