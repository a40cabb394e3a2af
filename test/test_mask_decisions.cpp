// The depth mask stage's bookkeeping (core/detection/mask_decisions.h):
// which boxes are masked, the counts, the drawing, and the camera_info relay,
// against values worked out by hand.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include <opencv2/core.hpp>

#include "fisheye_mapping/core/detection/held_depth.h"
#include "fisheye_mapping/core/detection/mask_decisions.h"

namespace fm = fisheye_mapping;
using Decision = fm::VehicleMotionTracker::Decision;

namespace {
fm::Detection box(float x0, float y0, float x1, float y1) {
  fm::Detection d;
  d.x_min = x0, d.y_min = y0, d.x_max = x1, d.y_max = y1;
  return d;
}
Decision decided(fm::VehicleMotion m, int track = -1) {
  Decision d;
  d.motion = m;
  d.track = track;
  return d;
}
}  // namespace

TEST(MaskDecisions, ParkedVehiclesStayUnlessMaskParked) {
  const std::vector<fm::Detection> boxes{box(0, 0, 1, 1), box(2, 2, 3, 3), box(4, 4, 5, 5), box(6, 6, 7, 7)};
  const std::vector<Decision> d{decided(fm::VehicleMotion::Moving), decided(fm::VehicleMotion::Parked),
                                decided(fm::VehicleMotion::Undecided)};  // the fourth box: no decision
  const auto kept = fm::boxesToMask(boxes, d, false);
  ASSERT_EQ(kept.size(), 3u);
  EXPECT_EQ(kept[0].x_min, 0.f);
  EXPECT_EQ(kept[1].x_min, 4.f);
  EXPECT_EQ(kept[2].x_min, 6.f);
  EXPECT_EQ(fm::boxesToMask(boxes, d, true).size(), 4u);
}

TEST(MaskDecisions, CountsByKind) {
  fm::MotionCounts c;
  c.add({decided(fm::VehicleMotion::Moving), decided(fm::VehicleMotion::Parked), decided(fm::VehicleMotion::Parked)});
  c.add({decided(fm::VehicleMotion::Undecided)});
  EXPECT_EQ(c.text(), "1 / 2 / 1");
}

TEST(MaskDecisions, BoxesDrawnInTheirColourScaledToTheImage) {
  // Boxes of a 200 x 100 image drawn on a 100 x 50 colour image: scale 0.5.
  cv::Mat colour(50, 100, CV_8UC3, cv::Scalar(0, 0, 0));
  const std::vector<fm::Detection> boxes{box(20, 40, 80, 90), box(120, 40, 180, 90),
                                         box(NAN, 0, 10, 10)};
  fm::drawVehicleDecisions(&colour, boxes, {decided(fm::VehicleMotion::Moving), decided(fm::VehicleMotion::Parked),
                                            decided(fm::VehicleMotion::Moving)},
                           200, 100);
  // Left edge of the first box at x = 10 (20 * 0.5), rows 20..45; the second's at x = 60.
  EXPECT_EQ(colour.at<cv::Vec3b>(30, 10), cv::Vec3b(0, 0, 255));
  EXPECT_EQ(colour.at<cv::Vec3b>(30, 60), cv::Vec3b(0, 200, 0));
  EXPECT_EQ(colour.at<cv::Vec3b>(30, 25), cv::Vec3b(0, 0, 0));  // inside a box: not filled
  EXPECT_EQ(colour.at<cv::Vec3b>(2, 2), cv::Vec3b(0, 0, 0));    // the non-finite box is not drawn
}

TEST(InfoRelay, AnOutputBeforeAnyInfoGetsTheFirstOne) {
  using Relay = fm::InfoRelay<int>;  // header: a frame number
  Relay r("/depth/camera_info");
  EXPECT_EQ(r.state("depth_masked/camera_info"),
            "none received on /depth/camera_info: depth_masked/camera_info not published");
  EXPECT_EQ(r.output(1, 640, 480), Relay::Action::kWait);
  EXPECT_TRUE(r.firstWait());
  EXPECT_EQ(r.output(2, 640, 480), Relay::Action::kWait);  // the newest waits, said once
  EXPECT_FALSE(r.firstWait());
  const auto waiting = r.info(640, 480);
  ASSERT_TRUE(waiting);
  EXPECT_EQ(waiting->header, 2);
  EXPECT_EQ(r.output(waiting->header, waiting->width, waiting->height), Relay::Action::kSend);
  EXPECT_FALSE(r.info(640, 480));  // nothing waits any more
  EXPECT_EQ(r.output(3, 640, 480), Relay::Action::kSend);
  EXPECT_EQ(r.state("x"), "republished from /depth/camera_info");
}

TEST(InfoRelay, AnInfoOfAnotherSizeIsNotSent) {
  using Relay = fm::InfoRelay<int>;
  Relay r("/depth/camera_info");
  r.info(320, 240);
  EXPECT_EQ(r.output(1, 640, 480), Relay::Action::kMismatch);
  EXPECT_EQ(r.problem(), "not republished: /depth/camera_info is 320x240, the depth 640x480");
  EXPECT_EQ(r.state("x"), r.problem());
  r.info(640, 480);
  EXPECT_EQ(r.output(2, 640, 480), Relay::Action::kSend);
  EXPECT_TRUE(r.problem().empty());
}

// VehicleDepthHold, counted by hand on a 20 x 10 depth map whose pixel
// (u, v) has range 100 v + u (boxes in pixels of the same size, margin 1; a
// pixel is inside when its centre u + 0.5 is): vehicle 7's box [2, 4] x
// [2, 4] masks pixels 1..4 x 1..4 (16), vehicle 9's [4, 6] x [2, 4] pixels
// 3..6 x 1..4, so columns 3..4 are both boxes'.
TEST(VehicleDepthHold, AVehicleDecidedParkedReleasesWhatItsBoxAloneMasked) {
  using M = fm::VehicleMotion;
  constexpr std::int64_t kS = 1000000000;
  cv::Mat depth(10, 20, CV_32FC1);
  for (int v = 0; v < 10; ++v)
    for (int u = 0; u < 20; ++u) depth.at<float>(v, u) = 100.f * v + u;
  depth.at<float>(1, 1) = std::numeric_limits<float>::quiet_NaN();  // no depth: nothing to hold
  fm::VehicleDepthHold hold(3.0);
  const std::vector<fm::Detection> two{box(2, 2, 4, 4), box(10, 2, 12, 4)};
  const std::vector<fm::Detection> overlap{box(2, 2, 4, 4), box(4, 2, 6, 4)};
  // Frame 1: vehicle 7 undecided (held: 16 pixels less the NaN one), vehicle 9 moving (not held).
  EXPECT_TRUE(hold.update(1 * kS, depth, two, {decided(M::Undecided, 7), decided(M::Moving, 9)}, 1.f, 20, 10).empty());
  EXPECT_EQ(hold.heldPixels(), 15u);
  // Frame 2: vehicle 7's box overlaps vehicle 9's (still masked): 7 holds
  // columns 1..2 alone (8 pixels less the NaN one).
  EXPECT_TRUE(hold.update(2 * kS, depth, overlap, {decided(M::Undecided, 7), decided(M::Moving, 9)}, 1.f, 20, 10).empty());
  EXPECT_EQ(hold.heldPixels(), 15u + 7u);
  // Frame 3: vehicle 7 is parked: both earlier frames come out, oldest first,
  // with the held pixels' ranges and NaN elsewhere; nothing is held any more.
  const auto out = hold.update(3 * kS, depth, two, {decided(M::Parked, 7), decided(M::Moving, 9)}, 1.f, 20, 10);
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].stamp_ns, 1 * kS);
  EXPECT_EQ(out[1].stamp_ns, 2 * kS);
  EXPECT_EQ(cv::countNonZero(out[0].depth == out[0].depth), 15);  // non-NaN pixels
  EXPECT_EQ(cv::countNonZero(out[1].depth == out[1].depth), 7);
  EXPECT_FLOAT_EQ(out[0].depth.at<float>(4, 4), 404.f);
  EXPECT_TRUE(std::isnan(out[0].depth.at<float>(5, 5))) << "outside the grown box";
  EXPECT_FLOAT_EQ(out[1].depth.at<float>(3, 2), 302.f);
  EXPECT_TRUE(std::isnan(out[1].depth.at<float>(3, 4))) << "vehicle 9's box covers it too";
  EXPECT_TRUE(std::isnan(out[0].depth.at<float>(3, 11))) << "the moving vehicle's";
  EXPECT_EQ(hold.heldPixels(), 0u);
  EXPECT_EQ(hold.releasedFrames(), 2u);
  EXPECT_EQ(hold.releasedPixels(), 22u);
  // Decided once: vehicle 7 masked again later (a parked vehicle's box placed
  // away from where it stands) is not held.
  EXPECT_TRUE(hold.update(4 * kS, depth, two, {decided(M::Undecided, 7), decided(M::Undecided, -1)}, 1.f, 20, 10).empty());
  EXPECT_EQ(hold.heldPixels(), 0u);
}

TEST(VehicleDepthHold, MovingOrTooOldDepthIsDroppedAndBadInputNamed) {
  using M = fm::VehicleMotion;
  constexpr std::int64_t kS = 1000000000;
  const cv::Mat depth(10, 20, CV_32FC1, cv::Scalar(5.f));
  const std::vector<fm::Detection> one{box(2, 2, 4, 4)};
  fm::VehicleDepthHold hold(1.0);
  hold.update(1 * kS, depth, one, {decided(M::Undecided, 3)}, 0.f, 20, 10);
  EXPECT_EQ(hold.heldPixels(), 4u);  // pixels 2..3 x 2..3
  EXPECT_TRUE(hold.update(2 * kS, depth, one, {decided(M::Moving, 3)}, 0.f, 20, 10).empty());
  EXPECT_EQ(hold.heldPixels(), 0u) << "a moving vehicle's depth is dropped";
  EXPECT_TRUE(hold.update(3 * kS, depth, one, {decided(M::Parked, 3)}, 0.f, 20, 10).empty()) << "nothing held for it";
  // Held 1 s: frame 10's depth is gone by frame 11.5.
  hold.update(10 * kS, depth, one, {decided(M::Undecided, 4)}, 0.f, 20, 10);
  hold.update(11 * kS + kS / 2, depth, {}, {}, 0.f, 20, 10);
  EXPECT_EQ(hold.heldPixels(), 0u);
  EXPECT_TRUE(hold.update(12 * kS, depth, one, {decided(M::Parked, 4)}, 0.f, 20, 10).empty());
  // A stamp going back drops what is held.
  hold.update(13 * kS, depth, one, {decided(M::Undecided, 5)}, 0.f, 20, 10);
  hold.update(2 * kS, depth, {}, {}, 0.f, 20, 10);
  EXPECT_EQ(hold.heldPixels(), 0u);
  // hold_time 0 holds nothing.
  fm::VehicleDepthHold none(0.0);
  none.update(1 * kS, depth, one, {decided(M::Undecided, 3)}, 0.f, 20, 10);
  EXPECT_EQ(none.heldPixels(), 0u);
  EXPECT_THROW(fm::VehicleDepthHold(-1.0), std::invalid_argument);
  EXPECT_THROW(hold.update(20 * kS, cv::Mat(10, 20, CV_8UC1), one, {decided(M::Undecided, 3)}, 0.f, 20, 10),
               std::invalid_argument);
  EXPECT_THROW(hold.update(20 * kS, depth, one, {}, 0.f, 20, 10), std::invalid_argument);
  EXPECT_THROW(hold.update(20 * kS, depth, one, {decided(M::Undecided, 3)}, 0.f, 0, 10), std::invalid_argument);
}
