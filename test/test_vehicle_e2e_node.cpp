// End-to-end rostest of vehicle.launch: a short synthetic drive (made here with
// make_drive on the small rig, played with --clock) goes through sync, plane
// sweep, ground-truth masking and TSDF fusion. Depth, masked depth, mesh and
// cloud must arrive with the reference camera's stamps and frames, no frame set
// may be dropped at this rate, and the final cloud must lie within 0.1 m of the
// drive's static ground-truth scene for at least 85 % of its points. The
// masked depth the nodelet chain published must equal what offline_mapper (the
// core FrameSetMapper) computes from the same bag and configuration.
#include <gtest/gtest.h>
#include <cv_bridge/cv_bridge.h>
#include <pcl_conversions/pcl_conversions.h>
#include <ros/ros.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <visualization_msgs/MarkerArray.h>

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <cmath>
#include <cstdlib>
#include <functional>
#include <map>
#include <mutex>
#include <set>
#include <string>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/core/eval/mesh_distance.h"
#include "ros_test_utils.h"

#include <opencv2/imgcodecs.hpp>

namespace fm = fisheye_mapping;

namespace {

using fisheye_mapping::test::waitFor;


}  // namespace

TEST(VehicleEndToEnd, StagesStampsAndMapAccuracy) {
  ros::NodeHandle nh;
  const std::string dir = "/tmp/fm_vehicle_e2e_" + std::to_string(getpid());
  const std::string config = FM_CONFIG_DIR "/rig";
  const int frame_sets = 10;  // 2 s at 5 Hz
  const std::string make = std::string(FM_MAKE_DRIVE) + " --out " + dir + " --camchain " + config +
                           "/default_camchain.yaml --mount " + config + "/default_mount.yaml" +
                           " --preset urban --seed 5 --duration 2 --rate 5 > " + dir + ".log 2>&1";
  ASSERT_EQ(std::system(make.c_str()), 0) << make;

  std::mutex mu;
  std::set<uint64_t> frames, depth, masked;
  std::map<uint64_t, cv::Mat> masked_depth;
  std::set<std::string> depth_frames, masked_frames, mesh_frames;
  sensor_msgs::PointCloud2ConstPtr cloud;
  int mesh_msgs = 0;
  auto s1 = nh.subscribe<fm::CameraFrameSet>("/fisheye_mapping/frames", 50, [&](const fm::CameraFrameSetConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    frames.insert(m->header.stamp.toNSec());
  });
  auto s2 = nh.subscribe<sensor_msgs::Image>("/fisheye_mapping/depth/image", 50, [&](const sensor_msgs::ImageConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    depth.insert(m->header.stamp.toNSec());
    depth_frames.insert(m->header.frame_id);
  });
  auto s3 = nh.subscribe<sensor_msgs::Image>("/fisheye_mapping/depth_masked/image", 50, [&](const sensor_msgs::ImageConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    masked.insert(m->header.stamp.toNSec());
    masked_frames.insert(m->header.frame_id);
    masked_depth[m->header.stamp.toNSec()] = cv_bridge::toCvCopy(m)->image;
  });
  auto s4 = nh.subscribe<visualization_msgs::MarkerArray>("/fisheye_mapping/tsdf/mesh", 50, [&](const visualization_msgs::MarkerArrayConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    ++mesh_msgs;
    for (const auto& k : m->markers) mesh_frames.insert(k.header.frame_id);
  });
  auto s5 = nh.subscribe<sensor_msgs::PointCloud2>("/fisheye_mapping/tsdf/cloud", 5, [&](const sensor_msgs::PointCloud2ConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    cloud = m;
  });
  ros::AsyncSpinner spinner(2);
  spinner.start();
  // Every stage subscribed (lazy subscriptions chain back to the cameras).
  ASSERT_TRUE(waitFor([&] { return s3.getNumPublishers() > 0 && s5.getNumPublishers() > 0; }, 60.0));
  ros::WallDuration(3.0).sleep();

  // Paced playback (paced_player): each frame set goes out once the TSDF stage
  // has finished the previous one, so the test holds at any machine speed
  // (an instrumented build included); it returns when the drive is done.
  ros::param::set("/e2e_player/bag", dir + "/drive.bag");
  ros::param::set("/e2e_player/camchain", config + "/default_camchain.yaml");
  ros::param::set("/e2e_player/mount", config + "/default_mount.yaml");
  ros::param::set("/e2e_player/hold", false);
  ros::param::set("/e2e_player/done_topic", "/fisheye_mapping/tsdf/fusion_done");
  const std::string play = std::string(FM_PACED_PLAYER) + " __name:=e2e_player >> " + dir + ".log 2>&1";
  ASSERT_EQ(std::system(play.c_str()), 0) << play;
  ASSERT_TRUE(waitFor([&] {
    std::lock_guard<std::mutex> l(mu);
    return masked.size() >= frames.size() && !frames.empty();
  }, 30.0));
  ros::WallDuration(2.0).sleep();  // last mesh / cloud publish (every 0.25 s of sim time... and wall)

  std::lock_guard<std::mutex> l(mu);
  EXPECT_EQ(int(frames.size()), frame_sets) << "frame sets dropped by the sync";
  EXPECT_EQ(depth, frames) << "a frame set got no depth";
  EXPECT_EQ(masked, frames) << "a depth map got no masked depth";
  EXPECT_EQ(depth_frames, std::set<std::string>{"cam0_optical_frame"});
  EXPECT_EQ(masked_frames, std::set<std::string>{"cam0_optical_frame"});
  EXPECT_GT(mesh_msgs, 0);
  EXPECT_EQ(mesh_frames, std::set<std::string>{"map"});
  ASSERT_TRUE(cloud);
  EXPECT_EQ(cloud->header.frame_id, "map");
  EXPECT_TRUE(frames.count(cloud->header.stamp.toNSec())) << "cloud stamp is not a frame set's";

  pcl::PointCloud<pcl::PointXYZ> pc;
  pcl::fromROSMsg(*cloud, pc);
  std::vector<Eigen::Vector3f> pts;
  for (const auto& p : pc) pts.emplace_back(p.x, p.y, p.z);
  ASSERT_GT(pts.size(), 500u);
  const auto gt = fm::MeshDistance::fromPly(dir + "/static_scene.ply", 0.5f);
  const double within = gt.fractionWithin(pts, 0.1f);
  std::printf("end-to-end: %zu frame sets, %zu cloud points, %.1f %% within 0.1 m of the static scene\n",
              frames.size(), pts.size(), 100 * within);
  EXPECT_GE(within, 0.85);

  // The same frame sets through offline_mapper (core FrameSetMapper) with the
  // launch's configuration: the same masked depth, pixel for pixel.
  const std::string offline = std::string(FM_OFFLINE_MAPPER) + " --bag " + dir + "/drive.bag --camchain " + config +
                              "/default_camchain.yaml --mount " + config + "/default_mount.yaml --out " + dir +
                              "/offline --config " FM_TEST_DATA_DIR "/vehicle_e2e.yaml --detector ground_truth" +
                              " --frames 3 --quiet --save-depth " + dir + "/offline_depth >> " + dir + ".log 2>&1";
  ASSERT_EQ(std::system(offline.c_str()), 0) << offline;
  int compared = 0;
  for (const auto& [stamp, topic_depth] : masked_depth) {
    const cv::Mat mine = cv::imread(dir + "/offline_depth/" + std::to_string(stamp) + ".tiff", cv::IMREAD_UNCHANGED);
    if (mine.empty()) continue;  // offline_mapper mapped the first 3 frame sets only
    ++compared;
    ASSERT_EQ(mine.type(), CV_32FC1);
    ASSERT_EQ(mine.size(), topic_depth.size());
    size_t same = 0, valid = 0;
    double max_diff = 0;
    for (int v = 0; v < mine.rows; ++v) {
      for (int u = 0; u < mine.cols; ++u) {
        const float a = mine.at<float>(v, u), b = topic_depth.at<float>(v, u);
        if (std::isnan(a) || std::isnan(b)) {
          same += std::isnan(a) && std::isnan(b);
          continue;
        }
        ++valid, ++same;
        max_diff = std::max(max_diff, double(std::fabs(a - b)));
      }
    }
    std::printf("frame set %llu: offline_mapper vs nodelets: %zu of %d pixels agree (valid %zu), max |diff| %.2e m\n",
                (unsigned long long)stamp, same, mine.rows * mine.cols, valid, max_diff);
    EXPECT_EQ(same, size_t(mine.rows) * mine.cols) << "valid pixels differ at stamp " << stamp;
    EXPECT_GT(valid, size_t(mine.rows) * mine.cols / 10);
    EXPECT_LE(max_diff, 1e-4);
  }
  EXPECT_EQ(compared, 3);
  std::system(("rm -rf " + dir + " " + dir + ".log").c_str());
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_vehicle_e2e");
  return RUN_ALL_TESTS();
}
