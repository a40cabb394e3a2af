// Depth masking by boxes (pixels counted by hand) and stamp pairing of depth and detections.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <string>

#include "fisheye_mapping/core/detection/depth_mask.h"

using namespace fisheye_mapping;
namespace fm = fisheye_mapping;

namespace {
Detection box(float x0, float y0, float x1, float y1) {
  Detection d;
  d.x_min = x0, d.y_min = y0, d.x_max = x1, d.y_max = y1;
  d.class_name = "car";
  return d;
}
int countNaN(const cv::Mat& d) {
  int n = 0;
  for (int v = 0; v < d.rows; ++v)
    for (int u = 0; u < d.cols; ++u) n += std::isnan(d.at<float>(v, u));
  return n;
}
}  // namespace

TEST(MaskDepth, BoxWithMarginByHand) {
  cv::Mat depth(20, 30, CV_32FC1, cv::Scalar(7.f));
  // Box (10.0, 4.0)-(14.0, 6.0): centres 10.5..13.5 and 4.5, 5.5 -> 4 x 2 pixels.
  cv::Mat mask = maskDepthBoxes(depth, {box(10, 4, 14, 6)}, 0.f, 30, 20);
  EXPECT_EQ(countNaN(depth), 8);
  EXPECT_EQ(cv::countNonZero(mask), 8);
  EXPECT_TRUE(std::isnan(depth.at<float>(4, 10)));
  EXPECT_TRUE(std::isnan(depth.at<float>(5, 13)));
  EXPECT_FLOAT_EQ(depth.at<float>(6, 13), 7.f);
  EXPECT_FLOAT_EQ(depth.at<float>(5, 14), 7.f);
  // Margin 2: (8, 2)-(16, 8) -> 8 x 6 pixels.
  depth.setTo(7.f);
  mask = maskDepthBoxes(depth, {box(10, 4, 14, 6)}, 2.f, 30, 20);
  EXPECT_EQ(countNaN(depth), 48);
  // Clipped at the border, and two overlapping boxes count once.
  depth.setTo(7.f);
  mask = maskDepthBoxes(depth, {box(-5, -5, 3, 2), box(1, 0, 4, 2)}, 0.f, 30, 20);
  EXPECT_EQ(countNaN(depth), 8);  // columns 0..3, rows 0..1
}

TEST(MaskDepth, ScalesBoxesToHalfResolutionDepth) {
  cv::Mat depth(10, 15, CV_32FC1, cv::Scalar(3.f));
  // Box in a 30x20 image (8, 4)-(16, 8) -> depth pixels (4, 2)-(8, 4): 4 x 2.
  maskDepthBoxes(depth, {box(8, 4, 16, 8)}, 0.f, 30, 20);
  EXPECT_EQ(countNaN(depth), 8);
  EXPECT_TRUE(std::isnan(depth.at<float>(2, 4)));
}

TEST(MaskDepth, NoBoxesLeavesDepthUnchangedAndBadInputThrows) {
  cv::Mat depth(4, 4, CV_32FC1, cv::Scalar(1.f));
  depth.at<float>(0, 0) = NAN;
  const cv::Mat before = depth.clone();
  const cv::Mat mask = maskDepthBoxes(depth, {}, 3.f, 4, 4);
  EXPECT_EQ(cv::countNonZero(mask), 0);
  EXPECT_EQ(countNaN(depth), 1);
  EXPECT_FLOAT_EQ(depth.at<float>(3, 3), 1.f);
  // Non-finite box coordinates are ignored rather than masking everything.
  maskDepthBoxes(depth, {box(NAN, 0, 4, 4)}, 0.f, 4, 4);
  EXPECT_EQ(countNaN(depth), 1);
  cv::Mat wrong(4, 4, CV_16UC1);
  EXPECT_THROW(maskDepthBoxes(wrong, {}, 0.f, 4, 4), std::invalid_argument);
  EXPECT_THROW(maskDepthBoxes(depth, {}, 0.f, 0, 4), std::invalid_argument);
  EXPECT_THROW(maskDepthBoxes(depth, {}, -1.f, 4, 4), std::invalid_argument);
}

TEST(StampPairer, PairsExactStampsEitherOrder) {
  StampPairer<std::string, int> p(0.5);
  auto out = p.addDetections(100, 1, 0.0);  // detections first
  EXPECT_TRUE(out.empty());
  out = p.addDepth(100, "d100", 0.1);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].depth, "d100");
  ASSERT_TRUE(out[0].dets.has_value());
  EXPECT_EQ(*out[0].dets, 1);
  out = p.addDepth(200, "d200", 0.2);  // depth first
  EXPECT_TRUE(out.empty());
  out = p.addDetections(199, 9, 0.3);  // near but not equal stamp: no pairing
  EXPECT_TRUE(out.empty());
  out = p.addDetections(200, 2, 0.3);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].stamp, 200u);
  EXPECT_EQ(*out[0].dets, 2);
  EXPECT_EQ(p.timedOut(), 0u);
}

TEST(StampPairer, WaitThenPassThroughAndLateDetectionsCounted) {
  StampPairer<std::string, int> p(0.5);
  EXPECT_TRUE(p.addDepth(300, "d300", 1.0).empty());
  EXPECT_TRUE(p.poll(1.49).empty());
  auto out = p.poll(1.5);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].depth, "d300");
  EXPECT_FALSE(out[0].dets.has_value());
  EXPECT_EQ(p.timedOut(), 1u);
  out = p.addDetections(300, 3, 1.6);  // too late
  EXPECT_TRUE(out.empty());
  EXPECT_EQ(p.late(), 1u);
  EXPECT_EQ(p.pendingDetections(), 0u);
  // Wait 0: depth without waiting detections leaves at once.
  StampPairer<std::string, int> now(0.0);
  out = now.addDepth(5, "d5", 0.0);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_FALSE(out[0].dets.has_value());
}

TEST(StampPairer, BoundedQueues) {
  StampPairer<int, int> p(100.0, 3);
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(p.addDepth(i, i, 0.0).empty());
  auto out = p.addDepth(3, 3, 0.0);  // fourth waiting map pushes the oldest out
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].stamp, 0u);
  for (int i = 10; i < 20; ++i) p.addDetections(i, i, 0.0);
  EXPECT_EQ(p.pendingDetections(), 3u);
  // 19's detections are there, but it queues behind 2 and 3 (and pushes 1 out).
  out = p.addDepth(19, 19, 0.0);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].stamp, 1u);
  EXPECT_TRUE(out[0].queue_full);
  out = p.poll(100.0);
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(out[0].stamp, 2u);
  EXPECT_EQ(out[1].stamp, 3u);
  EXPECT_EQ(out[2].stamp, 19u);
  ASSERT_TRUE(out[2].dets.has_value());
  EXPECT_EQ(*out[2].dets, 19);
}

// A depth map whose detections came leaves only after every older one: the
// fusion stage skips a frame older than the last it fused (a paced demo lost
// every other frame set when the detector dropped the older of two images).
TEST(StampPairer, DepthMapsLeaveInTheOrderTheyCame) {
  StampPairer<int, int> p(0.5);
  EXPECT_TRUE(p.addDepth(1, 1, 0.0).empty());
  EXPECT_TRUE(p.addDepth(2, 2, 0.1).empty());
  EXPECT_TRUE(p.addDetections(2, 20, 0.2).empty());  // 2 is ready, 1 still waits
  EXPECT_EQ(p.pendingDepth(), 2u);
  auto out = p.addDetections(1, 10, 0.3);
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].stamp, 1u);
  EXPECT_EQ(*out[0].dets, 10);
  EXPECT_EQ(out[1].stamp, 2u);
  EXPECT_EQ(*out[1].dets, 20);
  // The older one's detections never come: it leaves unmasked at its wait's
  // end, the newer one right after it, with its detections.
  EXPECT_TRUE(p.addDepth(3, 3, 1.0).empty());
  EXPECT_TRUE(p.addDepth(4, 4, 1.1).empty());
  EXPECT_TRUE(p.addDetections(4, 40, 1.2).empty());
  EXPECT_TRUE(p.poll(1.49).empty());
  out = p.poll(1.5);
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].stamp, 3u);
  EXPECT_FALSE(out[0].dets.has_value());
  EXPECT_FALSE(out[0].queue_full);
  EXPECT_EQ(out[1].stamp, 4u);
  EXPECT_EQ(*out[1].dets, 40);
  EXPECT_EQ(p.timedOut(), 1u);
  EXPECT_EQ(p.pendingDepth(), 0u);
  // Detections of 3 now are late.
  EXPECT_TRUE(p.addDetections(3, 30, 1.6).empty());
  EXPECT_EQ(p.late(), 1u);
}

// max_pending reconfigured while depth maps wait: the next add releases the
// excess, oldest first, unmasked and marked as a queue overflow (not as a
// wait that ran out); detection sets beyond it are dropped and counted.
TEST(ReconfigureDetection, LowerMaxPendingReleasesTheExcessAsQueueFull) {
  fm::StampPairer<int, int> pairer(10.0, 5);
  for (std::uint64_t s = 1; s <= 4; ++s) EXPECT_TRUE(pairer.addDepth(s, int(s), 0.0).empty());
  pairer.setMaxPending(2);
  const auto out = pairer.addDepth(5, 5, 0.1);  // 5 waiting, 2 allowed: stamps 1, 2, 3 leave
  ASSERT_EQ(out.size(), 3u);
  for (std::size_t i = 0; i < out.size(); ++i) {
    EXPECT_EQ(out[i].stamp, i + 1);
    EXPECT_FALSE(out[i].dets.has_value());
    EXPECT_TRUE(out[i].queue_full);
  }
  EXPECT_EQ(pairer.pendingDepth(), 2u);
  // The wait running out is not a queue overflow.
  const auto timed_out = pairer.poll(10.5);
  ASSERT_EQ(timed_out.size(), 2u);
  EXPECT_FALSE(timed_out[0].queue_full);
  // Detection sets: 3 without depth, 2 kept, the oldest dropped.
  for (std::uint64_t s = 20; s < 23; ++s) pairer.addDetections(s, int(s), 11.0);
  EXPECT_EQ(pairer.pendingDetections(), 2u);
  EXPECT_EQ(pairer.detectionsDropped(), 1u);
}

