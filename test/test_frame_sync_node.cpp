// rostest: the FrameSync nodelet groups the rig's camera topics into frame sets
// in camera order with the reference header, drops and counts incomplete sets
// and wrongly sized images, reports a silent camera by name in /diagnostics,
// drops small steps back in time and resets when time goes back further.
#include <cv_bridge/cv_bridge.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <ros/ros.h>

#include <functional>
#include <map>
#include <mutex>

#include "fisheye_mapping/CameraFrameSet.h"
#include "ros_test_utils.h"

namespace {

using fisheye_mapping::test::waitFor;


sensor_msgs::ImagePtr image(int w, int h, const ros::Time& t, const std::string& frame, int value) {
  std_msgs::Header hd;
  hd.stamp = t;
  hd.frame_id = frame;
  return cv_bridge::CvImage(hd, "mono8", cv::Mat(h, w, CV_8UC1, cv::Scalar(value))).toImageMsg();
}

}  // namespace

TEST(FrameSyncNode, GroupsDropsAndDiagnoses) {
  ros::NodeHandle nh;
  std::vector<ros::Publisher> cams;
  for (int c = 0; c < 3; ++c) cams.push_back(nh.advertise<sensor_msgs::Image>("/cam" + std::to_string(c) + "/image_raw", 10));
  std::mutex mu;
  std::map<uint64_t, fisheye_mapping::CameraFrameSetConstPtr> sets;
  diagnostic_msgs::DiagnosticStatus last;
  auto sub = nh.subscribe<fisheye_mapping::CameraFrameSet>("frames", 10, [&](const fisheye_mapping::CameraFrameSetConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    sets[m->header.stamp.toNSec()] = m;
  });
  auto dsub = nh.subscribe<diagnostic_msgs::DiagnosticArray>("/diagnostics", 10, [&](const diagnostic_msgs::DiagnosticArrayConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    for (const auto& s : m->status)
      if (s.name.find("frame sets") != std::string::npos) last = s;
  });
  ros::AsyncSpinner spinner(1);
  spinner.start();
  ASSERT_TRUE(waitFor([&] { return cams[0].getNumSubscribers() && cams[1].getNumSubscribers() && cams[2].getNumSubscribers(); }, 20.0))
      << "the sync did not subscribe the three camera topics";
  ros::WallDuration(0.5).sleep();

  // 1. A complete set, cameras arriving out of order.
  const ros::Time t1(100, 0);
  for (int c : {2, 0, 1}) cams[c].publish(image(256, 136, t1, "cam" + std::to_string(c), 10 + c));
  ASSERT_TRUE(waitFor([&] { std::lock_guard<std::mutex> l(mu); return sets.count(t1.toNSec()) > 0; }, 5.0));
  {
    std::lock_guard<std::mutex> l(mu);
    const auto& s = *sets[t1.toNSec()];
    EXPECT_EQ(s.header.frame_id, "cam0");
    ASSERT_EQ(s.images.size(), 3u);
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(s.camera_names[c], "cam" + std::to_string(c));
      EXPECT_EQ(s.images[c].data[0], 10 + c);
    }
  }
  // 2. cam2's image has the wrong size: no set at t2; the next complete set drops it.
  const ros::Time t2(101, 0), t3(102, 0);
  cams[0].publish(image(256, 136, t2, "cam0", 1));
  cams[1].publish(image(256, 136, t2, "cam1", 1));
  cams[2].publish(image(128, 68, t2, "cam2", 1));
  ros::WallDuration(0.3).sleep();
  for (int c = 0; c < 3; ++c) cams[c].publish(image(256, 136, t3, "cam" + std::to_string(c), 2));
  ASSERT_TRUE(waitFor([&] { std::lock_guard<std::mutex> l(mu); return sets.count(t3.toNSec()) > 0; }, 5.0));
  EXPECT_EQ(sets.count(t2.toNSec()), 0u);
  // 3. cam2 goes silent while the others go on: /diagnostics names it.
  for (int k = 0; k < 30; ++k) {
    const ros::Time t(103 + k, 0);
    cams[0].publish(image(256, 136, t, "cam0", 3));
    cams[1].publish(image(256, 136, t, "cam1", 3));
    ros::WallDuration(0.1).sleep();
  }
  ASSERT_TRUE(waitFor([&] {
    std::lock_guard<std::mutex> l(mu);
    return last.level == diagnostic_msgs::DiagnosticStatus::ERROR;
  }, 5.0));
  {
    std::lock_guard<std::mutex> l(mu);
    EXPECT_NE(last.message.find("cam2"), std::string::npos) << last.message;
    std::map<std::string, std::string> kv;
    for (const auto& v : last.values) kv[v.key] = v.value;
    EXPECT_EQ(kv["cam2 bad images"], "1");
    EXPECT_EQ(kv["frame sets out"], "2");
    EXPECT_GE(std::stoi(kv["incomplete sets dropped"]), 1);
    EXPECT_EQ(kv["time resets"], "0");
    EXPECT_EQ(kv["callback errors"], "0");
  }
  // 4. Time goes backwards (the player restarted): 0.3 s back is jitter
  // (dropped), 20 s back resets the sync; the next sets complete and the reset
  // is reported (WARN, the count, both stamps).
  const ros::Time t4(140, 0), jitter(139, 700000000), t5(120, 0), t6(120, 100000000);
  for (int c = 0; c < 3; ++c) cams[c].publish(image(256, 136, t4, "cam" + std::to_string(c), 4));
  ASSERT_TRUE(waitFor([&] { std::lock_guard<std::mutex> l(mu); return sets.count(t4.toNSec()) > 0; }, 5.0));
  for (int c = 0; c < 3; ++c) cams[c].publish(image(256, 136, jitter, "cam" + std::to_string(c), 4));
  ros::WallDuration(0.3).sleep();
  for (const ros::Time& t : {t5, t6}) {
    for (int c = 0; c < 3; ++c) cams[c].publish(image(256, 136, t, "cam" + std::to_string(c), 5));
    ASSERT_TRUE(waitFor([&] { std::lock_guard<std::mutex> l(mu); return sets.count(t.toNSec()) > 0; }, 5.0))
        << "no frame set at " << t << " after time went backwards";
  }
  EXPECT_EQ(sets.count(jitter.toNSec()), 0u);
  std::map<std::string, std::string> kv;
  ASSERT_TRUE(waitFor([&] {
    std::lock_guard<std::mutex> l(mu);
    kv.clear();
    for (const auto& v : last.values) kv[v.key] = v.value;
    return kv["time resets"] == "1" && last.level == diagnostic_msgs::DiagnosticStatus::WARN;
  }, 5.0)) << "the reset is not on /diagnostics: " << last.message;
  EXPECT_NE(kv["last time reset"].find("140.000 s -> 120.000 s"), std::string::npos) << kv["last time reset"];
  EXPECT_EQ(kv["out-of-order images dropped"], "3");
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_frame_sync_node");
  return RUN_ALL_TESTS();
}
