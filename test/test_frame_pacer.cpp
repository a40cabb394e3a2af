// FramePacer: when a paced player waits, worked out by hand for short
// message sequences.
#include <gtest/gtest.h>

#include <stdexcept>

#include "fisheye_mapping/core/sync/frame_pacer.h"

namespace fm = fisheye_mapping;
using Step = fm::FramePacer::Step;

TEST(FramePacer, WaitsForTheLastFrameSetBeforeEachNewReferenceImage) {
  fm::FramePacer pacer("/cam0/image_raw", {"/cam0/image_raw", "/cam1/image_raw"});
  // Set 1.0: nothing to wait for yet; poses and the other camera go out in order.
  EXPECT_EQ(pacer.next("/tf", 0.0).kind, Step::kPublish);
  EXPECT_EQ(pacer.next("/cam1/image_raw", 1.0).kind, Step::kPublish);
  EXPECT_EQ(pacer.next("/cam0/image_raw", 1.0).kind, Step::kPublish);
  EXPECT_EQ(pacer.framesBegun(), 1);
  // The next set's other camera and poses are not held back ...
  EXPECT_EQ(pacer.next("/tf", 1.05).kind, Step::kPublish);
  EXPECT_EQ(pacer.next("/cam1/image_raw", 1.1).kind, Step::kPublish);
  // ... its reference image waits for set 1.0.
  const Step s = pacer.next("/cam0/image_raw", 1.1);
  EXPECT_EQ(s.kind, Step::kWaitThenPublish);
  EXPECT_DOUBLE_EQ(s.wait_for, 1.0);
  EXPECT_EQ(pacer.framesBegun(), 2);
  // A repeated stamp on the reference (a second message of the same set) does not wait.
  EXPECT_EQ(pacer.next("/cam0/image_raw", 1.1).kind, Step::kPublish);
  EXPECT_EQ(pacer.framesBegun(), 2);
}

// Two sets in flight: set k+1's reference waits for set k-1, so the depth of
// k+1 can run while k is fused; the second set still waits for the first
// (the pipeline warms up on it); at the end the last two are still open.
TEST(FramePacer, TwoInFlightWaitForTheSetBeforeThePrevious) {
  fm::FramePacer pacer("/cam0/image_raw", {"/cam0/image_raw", "/cam1/image_raw"}, 2);
  EXPECT_EQ(pacer.next("/cam1/image_raw", 1.0).kind, Step::kPublish);
  EXPECT_EQ(pacer.next("/cam0/image_raw", 1.0).kind, Step::kPublish);
  EXPECT_EQ(pacer.next("/cam1/image_raw", 1.1).kind, Step::kPublish);
  Step s = pacer.next("/cam0/image_raw", 1.1);  // the second set: after the first
  EXPECT_EQ(s.kind, Step::kWaitThenPublish);
  EXPECT_DOUBLE_EQ(s.wait_for, 1.0);
  EXPECT_EQ(pacer.next("/tf", 1.15).kind, Step::kPublish);
  EXPECT_EQ(pacer.next("/cam0/image_raw", 1.2).kind, Step::kPublish);  // 1.1 and 1.2 in flight
  EXPECT_EQ(pacer.next("/cam0/image_raw", 1.2).kind, Step::kPublish);  // the same set again
  s = pacer.next("/cam0/image_raw", 1.3);
  EXPECT_EQ(s.kind, Step::kWaitThenPublish);
  EXPECT_DOUBLE_EQ(s.wait_for, 1.1);
  s = pacer.next("/cam0/image_raw", 1.4);
  EXPECT_EQ(s.kind, Step::kWaitThenPublish);
  EXPECT_DOUBLE_EQ(s.wait_for, 1.2);
  EXPECT_EQ(pacer.framesBegun(), 5);
  ASSERT_EQ(pacer.unwaited().size(), 2u);
  EXPECT_DOUBLE_EQ(pacer.unwaited()[0], 1.3);
  EXPECT_DOUBLE_EQ(pacer.unwaited()[1], 1.4);
  // One in flight: only the last set is open at the end.
  fm::FramePacer one("/cam0/image_raw", {"/cam0/image_raw"});
  one.next("/cam0/image_raw", 1.0);
  EXPECT_DOUBLE_EQ(one.next("/cam0/image_raw", 1.1).wait_for, 1.0);
  ASSERT_EQ(one.unwaited().size(), 1u);
  EXPECT_DOUBLE_EQ(one.unwaited()[0], 1.1);
}

TEST(FramePacer, StampsGoingBackwardsAreNamed) {
  fm::FramePacer pacer("/cam0/image_raw", {"/cam0/image_raw", "/cam1/image_raw"});
  pacer.next("/cam0/image_raw", 5.0);
  pacer.next("/cam1/image_raw", 5.0);
  const Step s = pacer.next("/cam1/image_raw", 4.5);
  EXPECT_EQ(s.kind, Step::kStampsBackwards);
  EXPECT_NE(s.error.find("/cam1/image_raw"), std::string::npos) << s.error;
  EXPECT_NE(s.error.find("4.500000 after 5.000000"), std::string::npos) << s.error;
  // Non-image topics are never judged.
  EXPECT_EQ(pacer.next("/tf", 0.0).kind, Step::kPublish);
}

TEST(FramePacer, BadTopicListsAreRejected) {
  EXPECT_THROW(fm::FramePacer("/cam9/image_raw", {"/cam0/image_raw"}), std::invalid_argument);
  EXPECT_THROW(fm::FramePacer("/cam0/image_raw", {"/cam0/image_raw", "/cam0/image_raw"}), std::invalid_argument);
  EXPECT_THROW(fm::FramePacer("/cam0/image_raw", {"/cam0/image_raw"}, 0), std::invalid_argument);
  EXPECT_THROW(fm::FramePacer("/cam0/image_raw", {"/cam0/image_raw"}, 17), std::invalid_argument);
}
