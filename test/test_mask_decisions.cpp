// The depth mask stage's bookkeeping (core/detection/mask_decisions.h):
// which boxes are masked, the counts, the drawing, and the camera_info relay,
// against values worked out by hand.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include "fisheye_mapping/core/detection/mask_decisions.h"

namespace fm = fisheye_mapping;
using Decision = fm::VehicleMotionTracker::Decision;

namespace {
fm::Detection box(float x0, float y0, float x1, float y1) {
  fm::Detection d;
  d.x_min = x0, d.y_min = y0, d.x_max = x1, d.y_max = y1;
  return d;
}
Decision decided(fm::VehicleMotion m) {
  Decision d;
  d.motion = m;
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
