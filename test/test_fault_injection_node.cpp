// rostest (issue 28): an exception thrown inside a stage's callback is logged,
// counted on /diagnostics, and the stage goes on. The test loads the Depth and
// Tsdf nodelets into its own process (nodelet::Loader, as a nodelet manager
// does) and installs a fault hook there (setFaultHook; this file is compiled
// in tests only, the nodelets only call faultPoint). The hook throws, as a bug
// or an allocation failure would:
//   "depth frame set"  std::bad_alloc in the depth stage's sweep, twice;
//   "tsdf fusion"      a non-standard exception (an int) in the fusion, twice;
//   "publish timer"    std::runtime_error in the mesh/cloud timer, three times;
//   "occupancy timer"  std::logic_error in the obstacle grid's timer, once.
// Then each stage must have skipped exactly those frames (no depth for the two
// frame sets, fusion_done "not fused" naming the error for the two depth
// frames), counted them on /diagnostics, and gone on: every later frame set
// gives depth, every later depth frame is fused, and the cloud, the mesh and
// the grid keep coming.
#include <gtest/gtest.h>

#include <atomic>
#include <map>
#include <mutex>
#include <new>
#include <set>
#include <stdexcept>
#include <string>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <nav_msgs/OccupancyGrid.h>
#include <nodelet/loader.h>
#include <ros/ros.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_broadcaster.h>

#include "fisheye_mapping/FrameDone.h"
#include "fisheye_mapping/ros/nodelet_glue.h"
#include "ros_test_utils.h"
#include "small_rig_frames.h"

namespace fm = fisheye_mapping;

namespace {

using fm::test::waitFor;

// The faults still to throw at each site, and those thrown.
std::mutex fault_mutex;
std::map<std::string, int> faults_left, faults_thrown;

void throwingHook(const char* site) {
  std::string s(site);
  {
    std::lock_guard<std::mutex> lock(fault_mutex);
    auto it = faults_left.find(s);
    if (it == faults_left.end() || it->second <= 0) return;
    --it->second;
    ++faults_thrown[s];
  }
  if (s == "depth frame set") throw std::bad_alloc();
  if (s == "tsdf fusion") throw 7;  // not a std::exception: the catch-all path
  if (s == "occupancy timer") throw std::logic_error("injected fault in the occupancy timer");
  throw std::runtime_error("injected fault in the " + s);
}

int thrown(const std::string& site) {
  std::lock_guard<std::mutex> lock(fault_mutex);
  return faults_thrown[site];
}

int left(const std::string& site) {
  std::lock_guard<std::mutex> lock(fault_mutex);
  return faults_left[site];
}

// The values of a status on /diagnostics, by status name ("depth: depth").
std::mutex diag_mutex;
std::map<std::string, std::map<std::string, std::string>> diag;

std::string diagValue(const std::string& status, const std::string& key) {
  std::lock_guard<std::mutex> lock(diag_mutex);
  auto s = diag.find(status);
  if (s == diag.end()) return "";
  auto v = s->second.find(key);
  return v == s->second.end() ? std::string() : v->second;
}

}  // namespace

TEST(FaultInjection, StagesCountExceptionsInTheirCallbacksAndGoOn) {
  ros::NodeHandle nh;
  const fm::Rig rig = fm::test::smallRig();
  cv::Mat truth;
  const fm::CameraFrameSet set = fm::test::renderedSet(rig, &truth);
  const Eigen::Isometry3d T_W_B = fm::synth::World(fm::test::smallRigWorld()).egoPose(3.0);

  tf2_ros::StaticTransformBroadcaster static_tf;
  tf2_ros::TransformBroadcaster tf;
  static_tf.sendTransform(fm::test::mountTransforms(rig, set.header.stamp));

  std::mutex m;
  std::set<ros::Time> depth_stamps;
  std::map<ros::Time, fm::FrameDone> done;
  int clouds_after_faults = 0, grids_after_faults = 0;
  size_t cloud_points = 0;
  auto sub_d = nh.subscribe<sensor_msgs::Image>("depth/image", 10, [&](const sensor_msgs::ImageConstPtr& d) {
    std::lock_guard<std::mutex> lock(m);
    depth_stamps.insert(d->header.stamp);
  });
  auto sub_f = nh.subscribe<fm::FrameDone>("tsdf/fusion_done", 20, [&](const fm::FrameDoneConstPtr& d) {
    std::lock_guard<std::mutex> lock(m);
    done[d->header.stamp] = *d;
  });
  auto sub_c = nh.subscribe<sensor_msgs::PointCloud2>("tsdf/cloud", 2, [&](const sensor_msgs::PointCloud2ConstPtr& c) {
    if (left("publish timer") > 0) return;
    std::lock_guard<std::mutex> lock(m);
    ++clouds_after_faults;
    cloud_points = c->width * c->height;
  });
  auto sub_g = nh.subscribe<nav_msgs::OccupancyGrid>("tsdf/occupancy", 2, [&](const nav_msgs::OccupancyGridConstPtr&) {
    if (left("occupancy timer") > 0) return;
    std::lock_guard<std::mutex> lock(m);
    ++grids_after_faults;
  });
  auto sub_diag = nh.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 20, boost::function<void(const diagnostic_msgs::DiagnosticArrayConstPtr&)>([](const auto& a) {
        std::lock_guard<std::mutex> lock(diag_mutex);
        for (const auto& st : a->status) {
          for (const auto& kv : st.values) diag[st.name][kv.key] = kv.value;
        }
      }));
  ros::Publisher pub = nh.advertise<fm::CameraFrameSet>("frames", 5);
  ASSERT_TRUE(waitFor([&] { return pub.getNumSubscribers() > 0; }, 30.0)) << "the depth stage never subscribed";

  // The timers' faults first, all spent before the map exists: the cloud
  // and the grid must then follow the map as it grows.
  {
    std::lock_guard<std::mutex> lock(fault_mutex);
    faults_left = {{"publish timer", 3}, {"occupancy timer", 1}};
  }
  ASSERT_TRUE(waitFor([] { return left("publish timer") == 0 && left("occupancy timer") == 0; }, 30.0))
      << "the TSDF's timers never ran";
  {
    std::lock_guard<std::mutex> lock(fault_mutex);
    faults_left["depth frame set"] = 2;
    faults_left["tsdf fusion"] = 2;
  }
  // One frame set at a time, 0.1 s apart, the vehicle standing still; each
  // waits until the depth stage has answered (depth, or a fault thrown).
  const int kSets = 10;
  std::vector<ros::Time> stamps;
  for (int k = 0; k < kSets; ++k) {
    const ros::Time stamp = set.header.stamp + ros::Duration(0.1 * k);
    stamps.push_back(stamp);
    geometry_msgs::TransformStamped t = tf2::eigenToTransform(T_W_B);
    t.header.stamp = stamp;
    t.header.frame_id = "map";
    t.child_frame_id = "base_link";
    tf.sendTransform(t);
    fm::CameraFrameSet s = set;
    s.header.stamp = stamp;
    for (auto& img : s.images) img.header.stamp = stamp;
    const int faults_before = thrown("depth frame set");
    pub.publish(s);
    ASSERT_TRUE(waitFor([&] {
      std::lock_guard<std::mutex> lock(m);
      return depth_stamps.count(stamp) || thrown("depth frame set") > faults_before;
    }, 60.0)) << "frame set " << k << ": no depth and no fault";
    // The depth frame (if any) fused or skipped before the next set.
    if (thrown("depth frame set") == faults_before) {
      ASSERT_TRUE(waitFor([&] {
        std::lock_guard<std::mutex> lock(m);
        return done.count(stamp) > 0;
      }, 30.0)) << "no tsdf/fusion_done for frame set " << k;
    }
  }
  // Both timers kept publishing after their faults, the cloud as the map grew.
  ASSERT_TRUE(waitFor([&] {
    std::lock_guard<std::mutex> lock(m);
    return clouds_after_faults >= 2 && grids_after_faults >= 2;
  }, 30.0)) << clouds_after_faults << " clouds and " << grids_after_faults << " grids after the timer faults";

  EXPECT_EQ(thrown("depth frame set"), 2);
  EXPECT_EQ(thrown("tsdf fusion"), 2);
  EXPECT_EQ(thrown("publish timer"), 3);
  EXPECT_EQ(thrown("occupancy timer"), 1);
  {
    std::lock_guard<std::mutex> lock(m);
    // The first two frame sets gave no depth; every other one did.
    for (int k = 0; k < kSets; ++k) EXPECT_EQ(depth_stamps.count(stamps[k]), k < 2 ? 0u : 1u) << "frame set " << k;
    // Of the depth frames, the first two were skipped naming the error, the rest fused.
    for (int k = 2; k < kSets; ++k) {
      ASSERT_EQ(done.count(stamps[k]), 1u) << "frame set " << k;
      const fm::FrameDone& d = done[stamps[k]];
      if (k < 4) {
        EXPECT_FALSE(d.fused) << "frame set " << k;
        EXPECT_EQ(d.reason, "error: unknown exception") << "frame set " << k;
      } else {
        EXPECT_TRUE(d.fused) << "frame set " << k << ": " << d.reason;
      }
    }
    EXPECT_GT(cloud_points, 1000u) << "the map after the faults";
  }
  // Counted and named on /diagnostics.
  ASSERT_TRUE(waitFor([] {
    return diagValue("depth: depth", "callback errors") == "2" && diagValue("tsdf: tsdf", "callback errors") == "6" &&
           diagValue("depth: depth", "outputs") == std::to_string(kSets - 2);
  }, 10.0)) << "depth: " << diagValue("depth: depth", "callback errors") << " callback errors, "
            << diagValue("depth: depth", "outputs") << " outputs; tsdf: " << diagValue("tsdf: tsdf", "callback errors")
            << " callback errors";
  EXPECT_NE(diagValue("depth: depth", "last callback error").find("std::bad_alloc"), std::string::npos)
      << diagValue("depth: depth", "last callback error");
  const std::string bad_input = diagValue("depth: depth", "dropped: bad input");  // "<n> in the last <w> s, <total> total"
  EXPECT_NE(bad_input.find(" s, 2 total"), std::string::npos) << bad_input;
  EXPECT_EQ(diagValue("tsdf: tsdf", "exceptions in depth callbacks"), "2");
  EXPECT_EQ(diagValue("tsdf: tsdf", "exceptions in timers"), "4");
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_fault_injection");
  fm::setFaultHook(&throwingHook);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  int rc = 1;
  {
    // The stages in this process, as in a nodelet manager; Tsdf reads the depth stage's output.
    nodelet::Loader loader(false);
    const nodelet::V_string no_argv;
    if (!loader.load("/depth", "fisheye_mapping/Depth", nodelet::M_string(), no_argv) ||
        !loader.load("/tsdf", "fisheye_mapping/Tsdf", {{"/depth_masked/image", "/depth/image"}}, no_argv)) {
      ROS_FATAL("test_fault_injection: the nodelets could not be loaded");
      return 1;
    }
    rc = RUN_ALL_TESTS();
    fm::setFaultHook(nullptr);
    loader.clear();
  }
  ros::shutdown();
  return rc;
}
