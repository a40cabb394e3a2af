// rostest: Detector + DepthMask nodelets as launched by users. Detections carry
// the image's stamp and frame and find the bicycle in dog.jpg (grey, as the
// fisheye cameras give); depth inside the moving objects' boxes becomes NaN;
// depth without detections passes through after the wait; empty detections
// leave depth unchanged; bad images and a corrupt model leave everything running.
#include <cv_bridge/cv_bridge.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>

#include <cmath>
#include <functional>
#include <map>

#include "fisheye_mapping/Detection2DArray.h"
#include "ros_test_utils.h"

namespace {

using fisheye_mapping::test::waitFor;


sensor_msgs::ImagePtr imageMsg(const cv::Mat& m, const std::string& encoding, const ros::Time& stamp) {
  std_msgs::Header h;
  h.stamp = stamp;
  h.frame_id = "cam0_optical";
  return cv_bridge::CvImage(h, encoding, m).toImageMsg();
}

float iou(const fisheye_mapping::Detection2D& d, float x0, float y0, float x1, float y1) {
  const float ix = std::max(0.f, std::min(d.x_max, x1) - std::max(d.x_min, x0));
  const float iy = std::max(0.f, std::min(d.y_max, y1) - std::max(d.y_min, y0));
  const float i = ix * iy;
  return i / ((d.x_max - d.x_min) * (d.y_max - d.y_min) + (x1 - x0) * (y1 - y0) - i);
}

}  // namespace

TEST(DynamicObjects, DetectMaskPassThroughAndSurviveBadInput) {
  ros::NodeHandle nh;
  const cv::Mat colour = cv::imread("/usr/share/darknet/data/dog.jpg", cv::IMREAD_COLOR);
  ASSERT_FALSE(colour.empty()) << "/usr/share/darknet/data/dog.jpg (Debian package darknet) missing";
  cv::Mat grey;
  cv::cvtColor(colour, grey, cv::COLOR_BGR2GRAY);
  const cv::Mat depth(grey.size(), CV_32FC1, cv::Scalar(5.f));

  ros::Publisher image_pub = nh.advertise<sensor_msgs::Image>("image", 5);
  ros::Publisher depth_pub = nh.advertise<sensor_msgs::Image>("depth", 5);
  ros::WallDuration(1.0).sleep();
  EXPECT_EQ(depth_pub.getNumSubscribers(), 0u) << "mask nodelet must subscribe only when someone listens";

  std::map<uint64_t, fisheye_mapping::Detection2DArrayConstPtr> dets, broken;
  std::map<uint64_t, sensor_msgs::ImageConstPtr> masked, masks, annotated;
  auto s1 = nh.subscribe<fisheye_mapping::Detection2DArray>(
      "detections", 10, [&](const fisheye_mapping::Detection2DArrayConstPtr& m) { dets[m->header.stamp.toNSec()] = m; });
  auto s2 = nh.subscribe<fisheye_mapping::Detection2DArray>(
      "broken/detections", 10,
      [&](const fisheye_mapping::Detection2DArrayConstPtr& m) { broken[m->header.stamp.toNSec()] = m; });
  auto s3 = nh.subscribe<sensor_msgs::Image>("depth_masked", 10,
                                             [&](const sensor_msgs::ImageConstPtr& m) { masked[m->header.stamp.toNSec()] = m; });
  auto s4 = nh.subscribe<sensor_msgs::Image>("depth_mask", 10,
                                             [&](const sensor_msgs::ImageConstPtr& m) { masks[m->header.stamp.toNSec()] = m; });
  auto s5 = nh.subscribe<sensor_msgs::Image>(
      "detections_image", 2, [&](const sensor_msgs::ImageConstPtr& m) { annotated[m->header.stamp.toNSec()] = m; });
  ros::AsyncSpinner spinner(1);
  spinner.start();
  // Both detectors live in one manager process: one connection on "image".
  ASSERT_TRUE(waitFor([&] { return image_pub.getNumSubscribers() > 0 && depth_pub.getNumSubscribers() > 0; }, 20.0))
      << "detectors / mask did not subscribe";
  ASSERT_TRUE(waitFor([&] { return s2.getNumPublishers() > 0; }, 10.0))
      << "the detector with the corrupt model did not come up";
  ros::WallDuration(0.5).sleep();

  // 1. A real frame: detections first or depth first, either way they pair.
  const ros::Time t1(1700000100, 123456789);
  image_pub.publish(imageMsg(grey, "mono8", t1));
  depth_pub.publish(imageMsg(depth, "32FC1", t1));
  ASSERT_TRUE(waitFor([&] { return dets.count(t1.toNSec()) && masked.count(t1.toNSec()); }, 20.0));
  const auto& d1 = *dets[t1.toNSec()];
  EXPECT_EQ(d1.header.frame_id, "cam0_optical");
  EXPECT_EQ(d1.image_width, 768u);
  EXPECT_EQ(d1.image_height, 576u);
  const fisheye_mapping::Detection2D* bike = nullptr;
  for (const auto& d : d1.detections) {
    EXPECT_NE(d.class_name, "dog") << "only moving classes are published";
    if (d.class_name == "bicycle") bike = &d;
  }
  ASSERT_NE(bike, nullptr);
  EXPECT_GE(iou(*bike, 125, 133, 567, 420), 0.5f);  // measured by hand
  const cv::Mat m1 = cv_bridge::toCvShare(masked[t1.toNSec()])->image;
  ASSERT_TRUE(waitFor([&] { return masks.count(t1.toNSec()) > 0; }, 5.0));
  const cv::Mat k1 = cv_bridge::toCvShare(masks[t1.toNSec()])->image;
  EXPECT_EQ(masked[t1.toNSec()]->header.frame_id, "cam0_optical");
  // Inside the bicycle's box grown by the 4 px margin: NaN; far outside every box: unchanged.
  const int cx = int((bike->x_min + bike->x_max) / 2), cy = int((bike->y_min + bike->y_max) / 2);
  EXPECT_TRUE(std::isnan(m1.at<float>(cy, cx)));
  EXPECT_TRUE(std::isnan(m1.at<float>(cy, int(bike->x_min) - 3)));
  EXPECT_FLOAT_EQ(m1.at<float>(cy, int(bike->x_min) - 6), bike->x_min > 6 ? 5.f : m1.at<float>(cy, 0));
  EXPECT_FLOAT_EQ(m1.at<float>(570, 5), 5.f);
  int nan_count = 0;
  for (int v = 0; v < m1.rows; ++v)
    for (int u = 0; u < m1.cols; ++u) nan_count += std::isnan(m1.at<float>(v, u));
  EXPECT_EQ(nan_count, cv::countNonZero(k1));
  EXPECT_GT(nan_count, 0.5 * (bike->x_max - bike->x_min) * (bike->y_max - bike->y_min));
  EXPECT_TRUE(annotated.count(t1.toNSec()));

  // 2. Depth whose image never comes: passes through unchanged after the 1 s wait.
  const ros::Time t2(1700000101, 0);
  const ros::WallTime sent = ros::WallTime::now();
  depth_pub.publish(imageMsg(depth, "32FC1", t2));
  ASSERT_TRUE(waitFor([&] { return masked.count(t2.toNSec()) > 0; }, 10.0));
  EXPECT_GE((ros::WallTime::now() - sent).toSec(), 0.9);
  EXPECT_EQ(cv::countNonZero(cv::Mat(cv_bridge::toCvShare(masked[t2.toNSec()])->image != 5.f)), 0);

  // 3. Bad input: a float image to the detectors, a mono8 "depth" to the mask.
  const ros::Time t3(1700000102, 0);
  image_pub.publish(imageMsg(depth, "32FC1", t3));
  depth_pub.publish(imageMsg(grey, "mono8", t3));
  ros::WallDuration(1.5).sleep();
  EXPECT_EQ(dets.count(t3.toNSec()), 0u);
  EXPECT_EQ(masked.count(t3.toNSec()), 0u);

  // 4. Still running: a black frame gives empty detections and unchanged depth.
  const ros::Time t4(1700000103, 0);
  image_pub.publish(imageMsg(cv::Mat(grey.size(), CV_8UC1, cv::Scalar(0)), "mono8", t4));
  depth_pub.publish(imageMsg(depth, "32FC1", t4));
  ASSERT_TRUE(waitFor([&] { return dets.count(t4.toNSec()) && masked.count(t4.toNSec()); }, 20.0));
  EXPECT_TRUE(dets[t4.toNSec()]->detections.empty());
  EXPECT_EQ(cv::countNonZero(cv::Mat(cv_bridge::toCvShare(masked[t4.toNSec()])->image != 5.f)), 0);
  // The detector with the corrupt model got every image and published nothing.
  EXPECT_TRUE(broken.empty());
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_dynamic_objects");
  return RUN_ALL_TESTS();
}
