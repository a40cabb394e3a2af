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
}
