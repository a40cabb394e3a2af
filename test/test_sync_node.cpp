// rostest: the Sync nodelet groups the rig's camera topics into frame sets
// in camera order with the reference header, drops and counts incomplete sets
// and wrongly sized images, reports a silent camera by name in /diagnostics,
// drops small steps back in time and resets when time goes back further;
// every set carries its cameras' CameraInfo; a second sync that builds its rig
// from camera_info topics and /tf_static gives the same sets; the rates on
// /diagnostics follow a steady stream without flicker; dynamic_reconfigure's
// policy / max_interval change which images pair.
#include <cv_bridge/cv_bridge.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <ros/ros.h>

#include <functional>
#include <map>
#include <mutex>

#include <dynamic_reconfigure/Reconfigure.h>
#include <ros/package.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/core/camera/rig.h"
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
      if (s.name == "sync: sync") last = s;
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
    // One CameraInfo per camera, with its image's header and the camchain's
    // intrinsics (test/data/small_rig_camchain.yaml, read here on its own).
    const std::string dir = ros::package::getPath("fisheye_mapping") + "/test/data/";
    const auto rig = fisheye_mapping::loadKalibrRig(dir + "small_rig_camchain.yaml", dir + "small_rig_mount.yaml");
    EXPECT_EQ(s.camera_infos.size(), 3u);
    for (size_t c = 0; c < s.camera_infos.size() && c < 3; ++c) {
      const auto& info = s.camera_infos[c];
      EXPECT_EQ(info.header.stamp, t1);
      EXPECT_EQ(info.header.frame_id, rig.cameras[c].frame_id);
      EXPECT_EQ(info.width, 256u);
      // Kalibr omni intrinsics [xi, fu, fv, pu, pv] = [0.98, 130, 130, 127.5,
      // 67.5], radtan [-0.02, 0.004, 0.0002, -0.0001] (every camera of the yaml).
      EXPECT_EQ(info.distortion_model, "omni");
      const std::vector<double> K{130.0, 0.0, 127.5, 0.0, 130.0, 67.5, 0.0, 0.0, 1.0};
      for (int k = 0; k < 9; ++k) EXPECT_DOUBLE_EQ(info.K[k], K[k]) << "camera " << c << " K[" << k << "]";
      EXPECT_EQ(info.D, (std::vector<double>{0.98, -0.02, 0.004, 0.0002, -0.0001})) << "camera " << c;
    }
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
  // Issue 28: the three jitter images are one frame set, dropped as stamps backwards.
  EXPECT_EQ(kv["frame sets dropped: stamps backwards"], "1");
  EXPECT_EQ(kv["frame sets dropped: duplicate stamp"], "0");
  EXPECT_EQ(std::stoi(kv["frame sets dropped"]),
            std::stoi(kv["frame sets dropped: stamps backwards"]) + std::stoi(kv["frame sets dropped: incomplete"]) +
                std::stoi(kv["frame sets dropped: old timeline"]));
}


namespace {

// The sync's reconfigure service (dynamic_reconfigure's set_parameters).
bool setSyncParams(const std::string& policy, double max_interval) {
  dynamic_reconfigure::Reconfigure srv;
  dynamic_reconfigure::StrParameter p;
  p.name = "policy";
  p.value = policy;
  srv.request.config.strs.push_back(p);
  dynamic_reconfigure::DoubleParameter d;
  d.name = "max_interval";
  d.value = max_interval;
  srv.request.config.doubles.push_back(d);
  return ros::service::waitForService("/sync/set_parameters", ros::Duration(10.0)) &&
         ros::service::call("/sync/set_parameters", srv);
}

}  // namespace

// A steady 10 Hz stream: each report's per-camera and output rates are close
// to 10 Hz (no 0 / 1 Hz flicker); the sets of the camera_info-built sync equal
// the camchain sync's; a 5 ms stamp spread pairs only after the policy turned
// approximate with a 10 ms max_interval.
TEST(FrameSyncNode, RatesCameraInfoRigAndReconfigure) {
  ros::NodeHandle nh;
  std::vector<ros::Publisher> cams, infos;
  for (int c = 0; c < 3; ++c) {
    cams.push_back(nh.advertise<sensor_msgs::Image>("/cam" + std::to_string(c) + "/image_raw", 10));
    infos.push_back(nh.advertise<sensor_msgs::CameraInfo>("/cam" + std::to_string(c) + "/camera_info", 10));
  }
  std::mutex mu;
  std::map<uint64_t, fisheye_mapping::CameraFrameSetConstPtr> sets, info_sets;
  std::vector<diagnostic_msgs::DiagnosticStatus> reports;
  auto sub = nh.subscribe<fisheye_mapping::CameraFrameSet>("/frames", 20, [&](const fisheye_mapping::CameraFrameSetConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    sets[m->header.stamp.toNSec()] = m;
  });
  auto isub = nh.subscribe<fisheye_mapping::CameraFrameSet>("/from_info/frames", 20, [&](const fisheye_mapping::CameraFrameSetConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    info_sets[m->header.stamp.toNSec()] = m;
  });
  auto dsub = nh.subscribe<diagnostic_msgs::DiagnosticArray>("/diagnostics", 50, [&](const diagnostic_msgs::DiagnosticArrayConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    for (const auto& s : m->status)
      if (s.name == "sync: sync") reports.push_back(s);
  });
  ros::AsyncSpinner spinner(1);
  spinner.start();
  ros::WallDuration(1.0).sleep();
  // 1. 10 Hz for 6 s; the CameraInfos at 10 Hz as a driver sends them (those
  // the camchain sync attached to its latest set: checked against the yaml by
  // the test above).
  ros::Time t(300, 0);
  const ros::WallTime start = ros::WallTime::now();
  std::size_t first_report = 0;
  for (int k = 0; k < 60; ++k, t += ros::Duration(0.1)) {
    for (int c = 0; c < 3; ++c) {
      {
        std::lock_guard<std::mutex> l(mu);
        if (!sets.empty()) {
          sensor_msgs::CameraInfo info = sets.rbegin()->second->camera_infos.at(c);
          info.header.stamp = t;
          infos[c].publish(info);
        }
      }
      cams[c].publish(image(256, 136, t, "cam" + std::to_string(c), 6));
    }
    if (k == 30) {
      std::lock_guard<std::mutex> l(mu);
      first_report = reports.size();  // from 3 s on: the 2 s window holds the steady stream only
    }
    ros::WallDuration(std::max(0.0, start.toSec() + 0.1 * (k + 1) - ros::WallTime::now().toSec())).sleep();
  }
  ros::WallDuration(0.5).sleep();
  std::lock_guard<std::mutex> l(mu);
  ASSERT_GE(reports.size() - first_report, 2u) << "fewer than two reports in 3 s";
  for (std::size_t i = first_report; i < reports.size(); ++i) {
    std::map<std::string, std::string> kv;
    for (const auto& v : reports[i].values) kv[v.key] = v.value;
    for (const char* key : {"cam0 rate (Hz)", "cam2 rate (Hz)", "output rate (Hz)"}) {
      ASSERT_TRUE(kv.count(key)) << key;
      EXPECT_NEAR(std::stod(kv[key]), 10.0, 1.5) << key << " in report " << i;
    }
    for (const char* key : {"input rate (Hz)", "processing time last/mean/max (ms)", "frame sets out", "tf failures"})
      EXPECT_TRUE(kv.count(key)) << key;
  }
  // 2. The camera_info sync (its rig from /camN/camera_info and /tf_static)
  // put out the same sets, with the same CameraInfos, once its rig was built.
  ASSERT_GE(info_sets.size(), 20u) << "the camera_info sync put out too few sets";
  for (const auto& [stamp, s] : info_sets) {
    ASSERT_TRUE(sets.count(stamp)) << stamp;
    const auto& a = *sets[stamp];
    EXPECT_EQ(s->camera_names, a.camera_names);
    ASSERT_EQ(s->camera_infos.size(), 3u);
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(s->camera_infos[c].header.frame_id, a.camera_infos[c].header.frame_id);
      EXPECT_EQ(s->camera_infos[c].distortion_model, a.camera_infos[c].distortion_model);
      for (int k = 0; k < 9; ++k) EXPECT_DOUBLE_EQ(s->camera_infos[c].K[k], a.camera_infos[c].K[k]);
      EXPECT_EQ(s->camera_infos[c].D, a.camera_infos[c].D);
    }
  }
}

TEST(FrameSyncNode, ReconfiguredPolicyPairsASpreadSet) {
  ros::NodeHandle nh;
  std::vector<ros::Publisher> cams;
  for (int c = 0; c < 3; ++c) cams.push_back(nh.advertise<sensor_msgs::Image>("/cam" + std::to_string(c) + "/image_raw", 10));
  std::mutex mu;
  std::map<uint64_t, fisheye_mapping::CameraFrameSetConstPtr> sets;
  auto sub = nh.subscribe<fisheye_mapping::CameraFrameSet>("/frames", 20, [&](const fisheye_mapping::CameraFrameSetConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    sets[m->header.stamp.toNSec()] = m;
  });
  ros::AsyncSpinner spinner(1);
  spinner.start();
  ASSERT_TRUE(waitFor([&] { return cams[0].getNumSubscribers() > 0; }, 10.0));
  ros::WallDuration(0.5).sleep();
  // cam1, cam2 5 ms after cam0: exact sync never pairs them.
  auto spread = [&](const ros::Time& t) {
    cams[0].publish(image(256, 136, t, "cam0", 7));
    cams[1].publish(image(256, 136, t + ros::Duration(0.005), "cam1", 7));
    cams[2].publish(image(256, 136, t + ros::Duration(0.005), "cam2", 7));
  };
  const ros::Time a(400, 0), b(401, 0);
  spread(a);
  ros::WallDuration(1.0).sleep();
  EXPECT_EQ(sets.count(a.toNSec()), 0u) << "exact policy paired stamps 5 ms apart";
  ASSERT_TRUE(setSyncParams("approximate", 0.01));
  ros::WallDuration(0.5).sleep();
  spread(b);
  EXPECT_TRUE(waitFor([&] { std::lock_guard<std::mutex> l(mu); return sets.count(b.toNSec()) > 0; }, 5.0))
      << "approximate policy, 10 ms max_interval, did not pair stamps 5 ms apart";
  ASSERT_TRUE(setSyncParams("exact", 0.005));
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_sync_node");
  return RUN_ALL_TESTS();
}
