// rostest: Detector + DepthMask nodelets as launched by users. Detections carry
// the image's stamp and frame and find the bicycle in dog.jpg (grey, as the
// fisheye cameras give); depth inside the moving objects' boxes becomes NaN;
// depth without detections passes through after the wait; empty detections
// leave depth unchanged; bad images and a corrupt model leave everything running.
// Then (issue 17): both stages' /diagnostics (keys, rates, drops by reason,
// ERROR without a model), dynamic_reconfigure changing what they do
// (margin_px, score_threshold, only_moving) and depth_masked/camera_info.
#include <cv_bridge/cv_bridge.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <dynamic_reconfigure/Reconfigure.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include <cmath>
#include <cstdlib>
#include <limits>
#include <set>
#include <functional>
#include <map>
#include <mutex>
#include <string>

#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/TrackedVehicleArray.h"
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

// The latest status of each diagnostics task, by name ("<node>: <task>").
struct Diagnostics {
  struct Status {
    int level = -1;
    std::string message;
    std::map<std::string, std::string> values;
  };
  std::mutex mutex;
  std::map<std::string, Status> latest;
  ros::Subscriber sub;
  explicit Diagnostics(ros::NodeHandle& nh) {
    sub = nh.subscribe<diagnostic_msgs::DiagnosticArray>("/diagnostics", 50,
                                                         [this](const diagnostic_msgs::DiagnosticArrayConstPtr& m) {
      std::lock_guard<std::mutex> l(mutex);
      for (const auto& s : m->status) {
        Status st;
        st.level = s.level;
        st.message = s.message;
        for (const auto& v : s.values) st.values[v.key] = v.value;
        latest[s.name] = st;
      }
    });
  }
  // The next status of `name` that satisfies `ok` (within `seconds`).
  bool waitFor(const std::string& name, const std::function<bool(const Status&)>& ok, Status* out,
               double seconds = 5.0) {
    return fisheye_mapping::test::waitFor([&] {
      std::lock_guard<std::mutex> l(mutex);
      auto it = latest.find(name);
      if (it == latest.end() || !ok(it->second)) return false;
      *out = it->second;
      return true;
    }, seconds);
  }
  void clear() {
    std::lock_guard<std::mutex> l(mutex);
    latest.clear();
  }
};

// "n in the last w s, N total" -> N.
long totalOf(const std::string& count) {
  const auto pos = count.find(", ");
  return pos == std::string::npos ? -1 : std::atol(count.c_str() + pos + 2);
}

// Sets parameters through the node's dynamic_reconfigure service; the answer
// is the configuration the node took.
dynamic_reconfigure::Config reconfigure(const std::string& node, const dynamic_reconfigure::Config& values) {
  dynamic_reconfigure::Reconfigure srv;
  srv.request.config = values;
  const std::string service = node + "/set_parameters";
  EXPECT_TRUE(ros::service::waitForService(service, 10000)) << service;
  EXPECT_TRUE(ros::service::call(service, srv)) << service;
  return srv.response.config;
}

dynamic_reconfigure::Config doubleParam(const std::string& name, double v) {
  dynamic_reconfigure::Config c;
  dynamic_reconfigure::DoubleParameter p;
  p.name = name;
  p.value = v;
  c.doubles.push_back(p);
  return c;
}

dynamic_reconfigure::Config boolParam(const std::string& name, bool v) {
  dynamic_reconfigure::Config c;
  dynamic_reconfigure::BoolParameter p;
  p.name = name;
  p.value = v;
  c.bools.push_back(p);
  return c;
}

template <class List>
double valueOf(const List& list, const std::string& name) {
  for (const auto& p : list)
    if (p.name == name) return p.value;
  ADD_FAILURE() << name << " missing from the reconfigure answer";
  return -1;
}

int nanCount(const cv::Mat& m) {
  int n = 0;
  for (int v = 0; v < m.rows; ++v)
    for (int u = 0; u < m.cols; ++u) n += std::isnan(m.at<float>(v, u));
  return n;
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
  ros::Publisher depth_pub = nh.advertise<sensor_msgs::Image>("depth/image", 5);
  ros::WallDuration(1.0).sleep();
  EXPECT_EQ(depth_pub.getNumSubscribers(), 0u) << "mask nodelet must subscribe only when someone listens";

  std::map<uint64_t, fisheye_mapping::Detection2DArrayConstPtr> dets, broken;
  std::map<uint64_t, sensor_msgs::ImageConstPtr> masked, masks, annotated;
  auto s1 = nh.subscribe<fisheye_mapping::Detection2DArray>(
      "detections", 10, [&](const fisheye_mapping::Detection2DArrayConstPtr& m) { dets[m->header.stamp.toNSec()] = m; });
  auto s2 = nh.subscribe<fisheye_mapping::Detection2DArray>(
      "broken/detections", 10,
      [&](const fisheye_mapping::Detection2DArrayConstPtr& m) { broken[m->header.stamp.toNSec()] = m; });
  auto s3 = nh.subscribe<sensor_msgs::Image>("depth_masked/image", 10,
                                             [&](const sensor_msgs::ImageConstPtr& m) { masked[m->header.stamp.toNSec()] = m; });
  auto s4 = nh.subscribe<sensor_msgs::Image>("depth_masked/mask", 10,
                                             [&](const sensor_msgs::ImageConstPtr& m) { masks[m->header.stamp.toNSec()] = m; });
  auto s5 = nh.subscribe<sensor_msgs::Image>(
      "detections/image", 2, [&](const sensor_msgs::ImageConstPtr& m) { annotated[m->header.stamp.toNSec()] = m; });
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

TEST(DynamicObjects, DiagnosticsReconfigureAndCameraInfo) {
  ros::NodeHandle nh;
  const cv::Mat colour = cv::imread("/usr/share/darknet/data/dog.jpg", cv::IMREAD_COLOR);
  ASSERT_FALSE(colour.empty());
  cv::Mat grey;
  cv::cvtColor(colour, grey, cv::COLOR_BGR2GRAY);
  const cv::Mat depth(grey.size(), CV_32FC1, cv::Scalar(5.f));
  Diagnostics diag(nh);
  std::mutex mu;
  std::map<uint64_t, fisheye_mapping::Detection2DArrayConstPtr> dets;
  std::map<uint64_t, sensor_msgs::ImageConstPtr> masked;
  std::map<uint64_t, sensor_msgs::CameraInfoConstPtr> infos;
  ros::Publisher image_pub = nh.advertise<sensor_msgs::Image>("image", 5);
  ros::Publisher depth_pub = nh.advertise<sensor_msgs::Image>("depth/image", 5);
  ros::Publisher info_pub = nh.advertise<sensor_msgs::CameraInfo>("depth/camera_info", 5);
  ros::Publisher det_pub = nh.advertise<fisheye_mapping::Detection2DArray>("detections", 5);
  auto s1 = nh.subscribe<fisheye_mapping::Detection2DArray>("detections", 10, [&](const fisheye_mapping::Detection2DArrayConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    dets[m->header.stamp.toNSec()] = m;
  });
  auto s2 = nh.subscribe<sensor_msgs::Image>("depth_masked/image", 10, [&](const sensor_msgs::ImageConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    masked[m->header.stamp.toNSec()] = m;
  });
  auto s3 = nh.subscribe<sensor_msgs::CameraInfo>("depth_masked/camera_info", 10, [&](const sensor_msgs::CameraInfoConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    infos[m->header.stamp.toNSec()] = m;
  });
  auto have = [&](auto& map, const ros::Time& t) {
    std::lock_guard<std::mutex> l(mu);
    return map.count(t.toNSec()) > 0;
  };
  ros::AsyncSpinner spinner(2);
  spinner.start();
  ASSERT_TRUE(waitFor([&] {
    return image_pub.getNumSubscribers() > 0 && depth_pub.getNumSubscribers() > 0 && info_pub.getNumSubscribers() > 0 &&
           det_pub.getNumSubscribers() > 0 && s3.getNumPublishers() > 0;
  }, 20.0)) << "the mask did not subscribe depth/camera_info or advertise depth_masked/camera_info";
  // Out of the 4 s diagnostics window (dynamic_objects.test): the rates below are this test's stream alone.
  ros::WallDuration(4.5).sleep();

  // 1. The effective thresholds are on the parameter server (nanodet.yaml's: 0.3 / 0.5).
  double score = 0, nms = 0;
  EXPECT_TRUE(nh.getParam("/detector/score_threshold", score));
  EXPECT_TRUE(nh.getParam("/detector/nms_threshold", nms));
  EXPECT_DOUBLE_EQ(score, 0.3);
  EXPECT_DOUBLE_EQ(nms, 0.5);

  // 2. Diagnostics before any camera_info: the mask says none arrived; the
  // corrupt-model detector is ERROR and counted the images as drops ("no
  // model"); the real detector counted the float image of the first test as a
  // bad image, not as a callback error.
  Diagnostics::Status st;
  ASSERT_TRUE(diag.waitFor("depth_mask: depth_mask", [](const auto&) { return true; }, &st));
  EXPECT_EQ(st.values["camera_info"].rfind("none received", 0), 0u) << st.values["camera_info"];
  ASSERT_TRUE(diag.waitFor("broken_detector: detector", [](const auto&) { return true; }, &st));
  EXPECT_EQ(st.level, diagnostic_msgs::DiagnosticStatus::ERROR);
  EXPECT_NE(st.message.find("no model"), std::string::npos) << st.message;
  EXPECT_EQ(totalOf(st.values["dropped: no model"]), 3) << "the 3 images of the first test";
  ASSERT_TRUE(diag.waitFor("detector: detector", [](const auto&) { return true; }, &st));
  EXPECT_EQ(totalOf(st.values["dropped: bad image"]), 1);
  EXPECT_EQ(st.values["callback errors"], "0");
  EXPECT_EQ(st.values["score threshold"], "0.3");

  // 3. A 2.5 Hz stream of 12 frames (image, depth and its camera_info). The
  // diagnostics reported in its last 1.6 s (1 Hz) are read: in the steady
  // state both estimates of the rate are the stream's 2.5 Hz (StageStats).
  sensor_msgs::CameraInfo info;
  info.header.frame_id = "cam0_optical";
  info.width = grey.cols;
  info.height = grey.rows;
  info.distortion_model = "omni";
  info.D = {0.9, -0.1, 0.01, 0.0, 0.0};
  info.K = {300, 0, 384, 0, 300, 288, 0, 0, 1};
  const int n = 12;
  const double period = 0.4;
  std::vector<ros::Time> stamps;
  for (int i = 0; i < n; ++i) {
    if (i == n - 4) diag.clear();
    const ros::Time t(1700000200 + i, 0);
    stamps.push_back(t);
    info.header.stamp = t;
    info_pub.publish(info);
    ros::WallDuration(0.02).sleep();  // the info first (another connection): no race for the depth map
    image_pub.publish(imageMsg(grey, "mono8", t));
    depth_pub.publish(imageMsg(depth, "32FC1", t));
    ros::WallDuration(period - 0.02).sleep();
  }
  for (const char* name : {"detector: detector", "depth_mask: depth_mask"}) {
    ASSERT_TRUE(diag.waitFor(name, [](const auto&) { return true; }, &st, 0.1)) << name << " not reported in 1.6 s";
    for (const char* key : {"input rate (Hz)", "output rate (Hz)", "inputs", "outputs", "last input (s ago)",
                            "processing time last/mean/max (ms)", "tf failures", "time resets", "callback errors"})
      EXPECT_TRUE(st.values.count(key)) << name << ": " << key;
    EXPECT_NEAR(std::atof(st.values["input rate (Hz)"].c_str()), 2.5, 0.4) << name;
    EXPECT_NEAR(std::atof(st.values["output rate (Hz)"].c_str()), 2.5, 0.4) << name;
    EXPECT_NE(st.values["processing time last/mean/max (ms)"], "none") << name;
    EXPECT_EQ(st.values["callback errors"], "0") << name;
  }
  ASSERT_TRUE(waitFor([&] { return have(masked, stamps.back()) && have(dets, stamps.back()); }, 10.0));
  // camera_info: republished with each masked depth's header (after the first,
  // whose info may race it on another connection).
  EXPECT_EQ(st.values["camera_info"].rfind("republished", 0), 0u) << st.values["camera_info"];
  for (int i = 1; i < n; ++i) {
    ASSERT_TRUE(waitFor([&] { return have(infos, stamps[i]); }, 2.0)) << "no depth_masked/camera_info for frame " << i;
    std::lock_guard<std::mutex> l(mu);
    const auto& ci = *infos[stamps[i].toNSec()];
    EXPECT_EQ(ci.header.stamp, masked[stamps[i].toNSec()]->header.stamp);
    EXPECT_EQ(ci.header.frame_id, masked[stamps[i].toNSec()]->header.frame_id);
    EXPECT_EQ(ci.width, 768u);
    EXPECT_EQ(ci.distortion_model, "omni");
    EXPECT_EQ(ci.D, info.D);
    EXPECT_EQ(ci.K, info.K);
  }
  float top_score = 0;
  {
    std::lock_guard<std::mutex> l(mu);
    for (const auto& t : stamps)
      for (const auto& d : dets[t.toNSec()]->detections) top_score = std::max(top_score, d.score);
  }
  ASSERT_GT(top_score, 0.3f) << "the stream's frames found nothing";

  // 4. Detections withheld: the depth map passes unmasked after the 1 s wait,
  // counted as a drop by that reason, and the mask WARNs naming it.
  ASSERT_TRUE(diag.waitFor("depth_mask: depth_mask", [](const auto&) { return true; }, &st));
  const long unmasked = std::atol(st.values["passed unmasked (no detections in time)"].c_str());
  const long dropped = totalOf(st.values["dropped: no detections in time (passed unmasked)"]);
  const ros::Time tw(1700000300, 0);
  depth_pub.publish(imageMsg(depth, "32FC1", tw));
  ASSERT_TRUE(waitFor([&] { return have(masked, tw); }, 5.0));
  diag.clear();
  ASSERT_TRUE(diag.waitFor("depth_mask: depth_mask", [](const auto&) { return true; }, &st, 3.0));
  EXPECT_EQ(std::atol(st.values["passed unmasked (no detections in time)"].c_str()), unmasked + 1);
  EXPECT_EQ(totalOf(st.values["dropped: no detections in time (passed unmasked)"]), dropped + 1);
  EXPECT_EQ(st.level, diagnostic_msgs::DiagnosticStatus::WARN);
  EXPECT_NE(st.message.find("no detections in time"), std::string::npos) << st.message;

  // 5. margin_px 10 -> 30 on one box of the test's own, x 100..200, y 100..150
  // in a 768x576 image: pixel u is masked when u + 0.5 lies in
  // [x_min - m, x_max + m], i.e. (100 + 2m) x (50 + 2m) pixels:
  // 120 x 70 = 8400 at 10 px, 160 x 110 = 17600 at 30 px (9200 more).
  auto maskedArea = [&](double margin, const ros::Time& t) {
    const auto answer = reconfigure("/depth_mask", doubleParam("margin_px", margin));
    EXPECT_DOUBLE_EQ(valueOf(answer.doubles, "margin_px"), margin);
    fisheye_mapping::Detection2DArray box;
    box.header.stamp = t;
    box.header.frame_id = "cam0_optical";
    box.image_width = 768;
    box.image_height = 576;
    fisheye_mapping::Detection2D d;
    d.class_name = "car";
    d.score = 0.9f;
    d.x_min = 100, d.y_min = 100, d.x_max = 200, d.y_max = 150;
    box.detections.push_back(d);
    det_pub.publish(box);
    depth_pub.publish(imageMsg(depth, "32FC1", t));
    EXPECT_TRUE(waitFor([&] { return have(masked, t); }, 5.0));
    std::lock_guard<std::mutex> l(mu);
    return masked.count(t.toNSec()) ? nanCount(cv_bridge::toCvShare(masked[t.toNSec()])->image) : -1;
  };
  const int area10 = maskedArea(10.0, ros::Time(1700000301, 0));
  const int area30 = maskedArea(30.0, ros::Time(1700000302, 0));
  EXPECT_EQ(area10, 8400);
  EXPECT_EQ(area30, 17600);
  EXPECT_EQ(area30 - area10, 9200);
  double margin = 0;
  EXPECT_TRUE(nh.getParam("/depth_mask/margin_px", margin));
  EXPECT_DOUBLE_EQ(margin, 30.0);

  // 6. score_threshold above every score (the stream's best was top_score):
  // no detections; back to 0.3: the bicycle again; only_moving off: the dog too.
  auto detectAt = [&](const ros::Time& t) -> fisheye_mapping::Detection2DArrayConstPtr {
    image_pub.publish(imageMsg(grey, "mono8", t));
    EXPECT_TRUE(waitFor([&] { return have(dets, t); }, 10.0));
    std::lock_guard<std::mutex> l(mu);
    return dets[t.toNSec()];
  };
  auto classes = [](const fisheye_mapping::Detection2DArrayConstPtr& m) {
    std::set<std::string> c;
    if (m)
      for (const auto& d : m->detections) c.insert(d.class_name);
    return c;
  };
  ASSERT_LT(top_score, 0.999f);
  auto answer = reconfigure("/detector", doubleParam("score_threshold", 0.999));
  EXPECT_NEAR(valueOf(answer.doubles, "score_threshold"), 0.999, 1e-9);
  const auto none = detectAt(ros::Time(1700000310, 0));
  ASSERT_TRUE(none);
  EXPECT_TRUE(none->detections.empty()) << none->detections.size() << " detections above 0.999";
  EXPECT_TRUE(nh.getParam("/detector/score_threshold", score));
  EXPECT_DOUBLE_EQ(score, 0.999);
  reconfigure("/detector", doubleParam("score_threshold", 0.3));
  EXPECT_TRUE(classes(detectAt(ros::Time(1700000311, 0))).count("bicycle"));
  answer = reconfigure("/detector", boolParam("only_moving", false));
  EXPECT_EQ(valueOf(answer.bools, "only_moving"), 0.0);
  EXPECT_TRUE(classes(detectAt(ros::Time(1700000312, 0))).count("dog")) << "only_moving off: every class";
  reconfigure("/detector", boolParam("only_moving", true));
  EXPECT_FALSE(classes(detectAt(ros::Time(1700000313, 0))).count("dog"));
}

// Issue 31: only what moves is masked. A static camera (tf map -> cam_street,
// latched) sees a parked car and a car driving across at 10 m/s, 10 m ahead,
// at 5 Hz; after the decision time the parked car's depth stays and the moving
// one's goes, depth_masked/vehicles says which is which, the parked car's
// depth masked while it was undecided comes out on depth_masked/held with
// those frames' stamps, and the diagnostics say what is tracked. Without the transform every vehicle is masked and the
// diagnostics name the missing transform.
TEST(DynamicObjects, OnlyMovingVehiclesAreMasked) {
  ros::NodeHandle nh;
  tf2_ros::StaticTransformBroadcaster tf_pub;
  geometry_msgs::TransformStamped T;
  T.header.stamp = ros::Time(1700000000, 0);
  T.header.frame_id = "map";
  T.child_frame_id = "cam_street";
  T.transform.rotation.w = 1.0;
  tf_pub.sendTransform(T);
  const int W = 640, H = 360;
  const double f = 320;
  sensor_msgs::CameraInfo info;
  info.width = W;
  info.height = H;
  info.distortion_model = "plumb_bob";
  info.D = {0, 0, 0, 0, 0};
  info.K = {f, 0, W / 2.0, 0, f, H / 2.0, 0, 0, 1};
  info.P = {f, 0, W / 2.0, 0, 0, f, H / 2.0, 0, 0, 0, 1, 0};
  info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  ros::Publisher info_pub = nh.advertise<sensor_msgs::CameraInfo>("depth/camera_info", 5, true);
  ros::Publisher depth_pub = nh.advertise<sensor_msgs::Image>("depth/image", 5);
  ros::Publisher det_pub = nh.advertise<fisheye_mapping::Detection2DArray>("detections", 5);
  std::mutex mu;
  std::map<uint64_t, sensor_msgs::ImageConstPtr> masked;
  std::map<uint64_t, fisheye_mapping::TrackedVehicleArrayConstPtr> vehicles;
  auto s1 = nh.subscribe<sensor_msgs::Image>("depth_masked/image", 20, [&](const sensor_msgs::ImageConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    masked[m->header.stamp.toNSec()] = m;
  });
  auto s2 = nh.subscribe<fisheye_mapping::TrackedVehicleArray>(
      "depth_masked/vehicles", 20, [&](const fisheye_mapping::TrackedVehicleArrayConstPtr& m) {
        std::lock_guard<std::mutex> l(mu);
        vehicles[m->header.stamp.toNSec()] = m;
      });
  std::map<uint64_t, sensor_msgs::ImageConstPtr> held;
  auto s3 = nh.subscribe<sensor_msgs::Image>("depth_masked/held", 20, [&](const sensor_msgs::ImageConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    held[m->header.stamp.toNSec()] = m;
  });
  Diagnostics diag(nh);
  ros::AsyncSpinner spinner(1);
  spinner.start();
  ASSERT_TRUE(waitFor([&] { return depth_pub.getNumSubscribers() > 0 && det_pub.getNumSubscribers() > 0; }, 20.0));
  info_pub.publish(info);
  ros::WallDuration(1.0).sleep();
  // Two car fronts 10 m ahead (the plane z = 10 inside their boxes) before a
  // facade 30 m ahead (where the static check finds that the crossing car's
  // body was not there 0.5 s before: moving): the parked one 5 m left, the
  // moving one crossing from the right at 10 m/s.
  auto frame = [&](int k, const std::string& frame_id) {
    const ros::Time t = ros::Time(1700000400, 0) + ros::Duration(0.2 * k);
    cv::Mat depth(H, W, CV_32FC1);
    for (int v = 0; v < H; ++v) {
      for (int u = 0; u < W; ++u) {
        const double rx = (u + 0.5 - W / 2.0) / f, ry = (v + 0.5 - H / 2.0) / f;
        depth.at<float>(v, u) = float(30.0 * std::sqrt(rx * rx + ry * ry + 1.0));  // range to z = 30
      }
    }
    fisheye_mapping::Detection2DArray dets;
    dets.header.stamp = t;
    dets.header.frame_id = frame_id;
    dets.image_width = W;
    dets.image_height = H;
    for (const double x : {-5.0, 6.0 - 10.0 * 0.2 * k}) {  // lateral position, camera x (right)
      fisheye_mapping::Detection2D d;
      d.class_name = "car";
      d.score = 0.9f;
      d.x_min = float(W / 2.0 + f * (x - 1.0) / 10.0), d.x_max = float(W / 2.0 + f * (x + 1.0) / 10.0);
      d.y_min = float(H / 2.0 - f * 0.5 / 10.0), d.y_max = float(H / 2.0 + f * 1.0 / 10.0);
      for (int v = int(d.y_min); v < int(d.y_max); ++v) {
        for (int u = int(d.x_min); u < int(d.x_max); ++u) {
          const double rx = (u + 0.5 - W / 2.0) / f, ry = (v + 0.5 - H / 2.0) / f;
          depth.at<float>(v, u) = float(10.0 * std::sqrt(rx * rx + ry * ry + 1.0));  // range to z = 10
        }
      }
      dets.detections.push_back(d);
    }
    det_pub.publish(dets);
    std_msgs::Header h;
    h.stamp = t;
    h.frame_id = frame_id;
    depth_pub.publish(cv_bridge::CvImage(h, "32FC1", depth).toImageMsg());
    EXPECT_TRUE(waitFor([&] {
      std::lock_guard<std::mutex> l(mu);
      return masked.count(t.toNSec()) && vehicles.count(t.toNSec());
    }, 5.0)) << "frame " << k;
    return t;
  };
  auto centreOf = [&](const ros::Time& t, int i) {
    std::lock_guard<std::mutex> l(mu);
    const auto& d = vehicles[t.toNSec()]->vehicles[i].detection;
    const int u = int((d.x_min + d.x_max) / 2), v = int((d.y_min + d.y_max) / 2);
    const float r = cv_bridge::toCvShare(masked[t.toNSec()])->image.at<float>(v, u);
    const double rx = (u + 0.5 - W / 2.0) / f, ry = (v + 0.5 - H / 2.0) / f;
    return r / float(std::sqrt(rx * rx + ry * ry + 1.0));  // z-depth: 10 where kept
  };
  ros::Time last;
  for (int k = 0; k < 5; ++k) last = frame(k, "cam_street");
  {
    std::lock_guard<std::mutex> l(mu);
    const auto first = vehicles[ros::Time(1700000400, 0).toNSec()];
    ASSERT_EQ(first->vehicles.size(), 2u);
    EXPECT_EQ(first->world_frame, "map");
    for (const auto& v : first->vehicles) {
      EXPECT_EQ(v.motion, fisheye_mapping::TrackedVehicle::UNDECIDED) << "a vehicle first seen is undecided";
      EXPECT_TRUE(v.masked);
    }
    const auto& now = *vehicles[last.toNSec()];
    ASSERT_EQ(now.vehicles.size(), 2u);
    EXPECT_EQ(now.vehicles[0].motion, fisheye_mapping::TrackedVehicle::PARKED);
    EXPECT_FALSE(now.vehicles[0].masked);
    EXPECT_NEAR(now.vehicles[0].position.x, -5.0, 0.2) << "map = camera frame: x right";
    EXPECT_NEAR(now.vehicles[0].position.z, 10.0, 0.01);
    EXPECT_EQ(now.vehicles[1].motion, fisheye_mapping::TrackedVehicle::MOVING);
    EXPECT_TRUE(now.vehicles[1].masked);
    EXPECT_NEAR(now.vehicles[1].speed, 10.0, 0.5);
  }
  EXPECT_NEAR(centreOf(last, 0), 10.0f, 1e-4) << "the parked car's depth stays";
  {
    // The frames in which the parked car was undecided (so masked) come out
    // on depth_masked/held, each with its own stamp: the car's depth there,
    // nothing of the moving car's.
    std::lock_guard<std::mutex> l(mu);
    std::vector<uint64_t> undecided;
    for (const auto& [stamp, v] : vehicles) {
      if (v->vehicles.size() == 2 && v->vehicles[0].motion == fisheye_mapping::TrackedVehicle::UNDECIDED) {
        undecided.push_back(stamp);
      }
    }
    ASSERT_FALSE(undecided.empty());
    ASSERT_EQ(held.size(), undecided.size());
    for (const uint64_t stamp : undecided) {
      ASSERT_TRUE(held.count(stamp)) << "frame at " << stamp;
      const cv::Mat h = cv_bridge::toCvShare(held[stamp])->image;
      for (int i = 0; i < 2; ++i) {
        const auto& d = vehicles[stamp]->vehicles[i].detection;
        const int u = int((d.x_min + d.x_max) / 2), v = int((d.y_min + d.y_max) / 2);
        const double rx = (u + 0.5 - W / 2.0) / f, ry = (v + 0.5 - H / 2.0) / f;
        const float z = h.at<float>(v, u) / float(std::sqrt(rx * rx + ry * ry + 1.0));
        if (i == 0) EXPECT_NEAR(z, 10.0f, 1e-4) << "the parked car's held depth";
        if (i == 1) EXPECT_TRUE(std::isnan(z)) << "the moving car's is never held out";
      }
      EXPECT_EQ(held[stamp]->header.frame_id, "cam_street");
    }
  }
  EXPECT_TRUE(std::isnan(centreOf(last, 1))) << "the moving car's depth goes";
  Diagnostics::Status st;
  EXPECT_TRUE(diag.waitFor("depth_mask: depth_mask", [](const Diagnostics::Status& s) {
    return s.values.count("vehicle motion") && s.values.at("vehicle motion") == "tracking in map";
  }, &st, 10.0)) << st.values["vehicle motion"];
  // No transform to the depth's frame: every vehicle undecided and masked, named.
  const ros::Time lost = frame(5, "cam_nowhere");
  EXPECT_TRUE(std::isnan(centreOf(lost, 0))) << "without a pose the parked car is masked too";
  {
    std::lock_guard<std::mutex> l(mu);
    for (const auto& v : vehicles[lost.toNSec()]->vehicles) {
      EXPECT_EQ(v.motion, fisheye_mapping::TrackedVehicle::UNDECIDED);
      EXPECT_TRUE(v.masked);
    }
  }
  EXPECT_TRUE(diag.waitFor("depth_mask: depth_mask", [](const Diagnostics::Status& s) {
    return s.values.count("vehicle motion") && s.values.at("vehicle motion").rfind("no tf map -> cam_nowhere", 0) == 0;
  }, &st, 10.0)) << st.values["vehicle motion"];
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_dynamic_objects");
  return RUN_ALL_TESTS();
}
