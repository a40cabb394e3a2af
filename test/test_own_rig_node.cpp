// rostest of docs/own_rig.md (test/launch/own_rig.test): a user's own rig and
// bag through vehicle.launch. A 2 s small-rig drive (make_drive) is turned by
// scripts/tools/make_own_rig_example into what a user brings: images on
// /front/{center,left,right}/image_raw (raw Images; ~images: compressed puts
// PNG CompressedImages on .../image_raw/compressed, which the sync takes only
// once it can decode them: Debian 12 packages no compressed image_transport
// plugin, see docs/own_rig.md), a Kalibr camchain naming the base topics, poses
// as odom -> base_link with base_link the rear axle 0.3 m above the road (the
// drive's map -> base_link raised 0.3 m along the vehicle's z, cam0 0.3 m lower
// in the mount: the cameras stay where they were, so odom is the drive's map
// and the road is z = 0 in odom, z = -0.3 in base_link), no /tf_static, a
// self-mask on the bottom 16 rows of cam0 and the example's config.yaml.
// This node starts vehicle.launch with the example's arguments (world_frame:=odom,
// publish_rig_tf:=true, detector:=ground_truth, rviz:=false), plays the bag
// with paced_player and checks: every frame set synced and given depth and
// masked depth in cam0's new optical frame; no depth in the self-masked rows;
// a TSDF cloud in odom within 0.25 m of the drive's static scene (90 % of its
// points: the small rig's 256x136 images give coarser depth than the default
// rig's, whose end-to-end test asks 0.1 m); the road seen just above the
// bonnet at z = -0.3 in base_link and z = 0 in odom.
#include <gtest/gtest.h>
#include <cv_bridge/cv_bridge.h>
#include <pcl_conversions/pcl_conversions.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <signal.h>
#include <sys/wait.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_msgs/TFMessage.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>
#include <unistd.h>

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/core/camera/camera_model.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/eval/mesh_distance.h"
#include "ros_test_utils.h"

namespace fm = fisheye_mapping;

namespace {

using fisheye_mapping::test::waitFor;

const int kFrameSets = 20;    // 2 s at 10 Hz
const int kMaskRows = 16;     // make_own_rig_example's default --mask-rows
const double kAxle = 0.3;     // ... and --axle-height

// Starts `cmd` under /bin/sh (which execs it: the pid is the command's).
pid_t spawn(const std::string& cmd) {
  const pid_t pid = fork();
  if (pid == 0) {
    execl("/bin/sh", "sh", "-c", ("exec " + cmd).c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  return pid;
}

// Stops the roslaunch this test started (SIGINT: it shuts its nodes down).
void stop(pid_t pid) {
  if (pid <= 0) return;
  kill(pid, SIGINT);
  for (int i = 0; i < 300; ++i) {
    if (waitpid(pid, nullptr, WNOHANG) == pid) return;
    usleep(100000);
  }
  kill(pid, SIGKILL);
  waitpid(pid, nullptr, 0);
}

// The value below which a fraction `q` of `v` lies.
double quantile(std::vector<double> v, double q) {
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(q * (v.size() - 1)), v.end());
  return v[std::size_t(q * (v.size() - 1))];
}

}  // namespace

TEST(OwnRig, OtherTopicsOdomPosesRaisedBaseAndSelfMaskGiveAMap) {
  ros::NodeHandle nh, pnh("~");
  const std::string images = pnh.param<std::string>("images", "raw");
  const std::string dir = "/tmp/fm_own_rig_" + std::to_string(getpid());
  const std::string ex = dir + "/example", log = dir + ".log";
  // ~drive: an existing small-rig drive of the same make_drive options (to
  // look at a failure without making it again); default: made here.
  std::string drive = pnh.param<std::string>("drive", "");
  if (drive.empty()) {
    drive = dir + "/drive";
    const std::string make = std::string(FM_MAKE_DRIVE) + " --out " + drive + " --camchain " FM_TEST_DATA_DIR
                             "/small_rig_camchain.yaml --mount " FM_TEST_DATA_DIR "/small_rig_mount.yaml"
                             " --preset urban --seed 9 --moving 3 --duration 2 --rate 10 > " + log + " 2>&1";
    ASSERT_EQ(std::system(make.c_str()), 0) << make;
  }
  const std::string example = "/usr/bin/python3 " FM_SCRIPTS_DIR "/tools/make_own_rig_example --drive " + drive +
                              " --out " + ex + " --images " + images + " >> " + log + " 2>&1";
  ASSERT_EQ(std::system(example.c_str()), 0) << example << " (log: " << log << ")";

  std::mutex mu;
  std::set<uint64_t> frames, depth, masked;
  std::set<std::string> depth_frames;
  std::map<uint64_t, cv::Mat> band_depth;  // cam0's depth, per stamp
  int masked_rows_with_depth = 0, valid_rows_above = 0;
  sensor_msgs::PointCloud2ConstPtr cloud;
  auto s1 = nh.subscribe<fm::CameraFrameSet>("/fisheye_mapping/frames", 50, [&](const fm::CameraFrameSetConstPtr& m) {
    std::lock_guard<std::mutex> l(mu);
    frames.insert(m->header.stamp.toNSec());
  });
  auto s2 = nh.subscribe<sensor_msgs::Image>("/fisheye_mapping/depth/image", 50, [&](const sensor_msgs::ImageConstPtr& m) {
    const cv::Mat d = cv_bridge::toCvShare(m)->image;
    std::lock_guard<std::mutex> l(mu);
    depth.insert(m->header.stamp.toNSec());
    depth_frames.insert(m->header.frame_id);
    band_depth[m->header.stamp.toNSec()] = d.clone();
    for (int v = 0; v < d.rows; ++v) {
      const int valid = cv::countNonZero(d.row(v) == d.row(v));  // NaN != NaN
      if (v >= d.rows - kMaskRows) masked_rows_with_depth += valid > 0;
      else if (v >= d.rows - 2 * kMaskRows) valid_rows_above += valid > 0;
    }
  });
  auto s3 = nh.subscribe<sensor_msgs::Image>("/fisheye_mapping/depth_masked/image", 50,
                                             [&](const sensor_msgs::ImageConstPtr& m) {
                                               std::lock_guard<std::mutex> l(mu);
                                               masked.insert(m->header.stamp.toNSec());
                                             });
  auto s4 = nh.subscribe<sensor_msgs::PointCloud2>("/fisheye_mapping/tsdf/cloud", 5,
                                                   [&](const sensor_msgs::PointCloud2ConstPtr& m) {
                                                     std::lock_guard<std::mutex> l(mu);
                                                     cloud = m;
                                                   });
  tf2_ros::Buffer tf_buffer(ros::Duration(30.0));
  tf2_ros::TransformListener tf_listener(tf_buffer);
  ros::AsyncSpinner spinner(2);
  spinner.start();

  // The example's own launch arguments (its launch.txt) but the bag: this node
  // plays it, so that it knows when the drive is over.
  const std::string launch =
      "roslaunch fisheye_mapping vehicle.launch bag:=none use_sim_time:=true rviz:=false camchain:=" + ex +
      "/camchain.yaml mount:=" + ex + "/mount.yaml config:=" + ex + "/config.yaml world_frame:=odom"
      " publish_rig_tf:=true reference_image:=/front/center/image_raw detector:=ground_truth"
      " gt_detections:=/front/center/detections_gt >> " + log + " 2>&1";
  const pid_t roslaunch = spawn(launch);
  ASSERT_GT(roslaunch, 0);
  const bool up = waitFor([&] { return s3.getNumPublishers() > 0 && s4.getNumPublishers() > 0; }, 60.0);
  if (!up) stop(roslaunch);
  ASSERT_TRUE(up) << "vehicle.launch did not come up: " << launch;
  ros::WallDuration(3.0).sleep();

  const std::string suffix = images == "compressed" ? "/compressed" : "";
  std::vector<std::string> topics;
  for (const char* cam : {"center", "left", "right"}) topics.push_back(std::string("/front/") + cam + "/image_raw" + suffix);
  ros::param::set("/own_rig_player/bag", ex + "/drive.bag");
  ros::param::set("/own_rig_player/image_topics", topics);
  ros::param::set("/own_rig_player/hold", false);
  ros::param::set("/own_rig_player/timeout", 60.0);
  ros::param::set("/own_rig_player/wait_subscribers", 30.0);
  ros::param::set("/own_rig_player/done_topic", "/fisheye_mapping/tsdf/fusion_done");
  const std::string play = std::string(FM_PACED_PLAYER) + " __name:=own_rig_player >> " + log + " 2>&1";
  const int played = std::system(play.c_str());
  const bool all_masked = waitFor([&] {
    std::lock_guard<std::mutex> l(mu);
    return !frames.empty() && masked.size() >= frames.size();
  }, 30.0);
  ros::WallDuration(2.0).sleep();  // the last cloud (published every 0.25 s)
  // cam0 in odom at every depth stamp: the bag's odom -> base_link and
  // rig_tf's base_link -> front_center_optical_frame. The poses are read from
  // the bag itself: this node's listener may connect to the player's /tf
  // after its first poses went out.
  std::map<uint64_t, geometry_msgs::TransformStamped> tf_camera;
  std::string tf_error;
  tf2_ros::Buffer drive_tf(ros::Duration(30.0));
  try {
    drive_tf.setTransform(tf_buffer.lookupTransform("base_link", "front_center_optical_frame", ros::Time(0)), "rig_tf",
                          true);
    rosbag::Bag bag(ex + "/drive.bag");
    for (const rosbag::MessageInstance& m : rosbag::View(bag, rosbag::TopicQuery("/tf"))) {
      if (const auto tf = m.instantiate<tf2_msgs::TFMessage>())
        for (const auto& t : tf->transforms) drive_tf.setTransform(t, "drive.bag");
    }
  } catch (const tf2::TransformException& e) {
    tf_error = std::string("rig_tf: ") + e.what();
  }
  {
    std::lock_guard<std::mutex> l(mu);
    for (const auto& [stamp, d] : band_depth) {
      try {
        tf_camera[stamp] = drive_tf.lookupTransform("odom", "front_center_optical_frame", ros::Time().fromNSec(stamp));
      } catch (const tf2::TransformException& e) {
        tf_error = e.what();
      }
    }
  }
  stop(roslaunch);
  ASSERT_EQ(played, 0) << play << " (the camera topics were not subscribed, or a frame set was not fused; log: " << log
                       << ")";
  ASSERT_TRUE(all_masked) << "not every frame set got masked depth";

  std::lock_guard<std::mutex> l(mu);
  EXPECT_EQ(int(frames.size()), kFrameSets) << "frame sets dropped by the sync";
  EXPECT_EQ(depth, frames) << "a frame set got no depth";
  EXPECT_EQ(masked, frames) << "a depth map got no masked depth";
  EXPECT_EQ(depth_frames, std::set<std::string>{"front_center_optical_frame"});
  // The self-mask: no depth in its rows; the rows just above it have depth.
  EXPECT_EQ(masked_rows_with_depth, 0);
  EXPECT_GT(valid_rows_above, kFrameSets * kMaskRows / 2);

  ASSERT_TRUE(cloud);
  EXPECT_EQ(cloud->header.frame_id, "odom");
  ASSERT_EQ(tf_error, "") << "no odom -> front_center_optical_frame at a depth stamp";
  pcl::PointCloud<pcl::PointXYZ> pc;
  pcl::fromROSMsg(*cloud, pc);
  std::vector<Eigen::Vector3f> pts;
  for (const auto& p : pc) pts.emplace_back(p.x, p.y, p.z);
  ASSERT_GT(pts.size(), 300u);
  // odom is the drive's map: the static scene is the truth there.
  const auto gt = fm::MeshDistance::fromPly(ex + "/static_scene.ply", 0.5f);
  const double within = gt.fractionWithin(pts, 0.25f);

  std::printf("own rig (%s images): %zu frame sets, %zu cloud points, %.1f %% within 0.25 m of the static scene\n",
              images.c_str(), frames.size(), pts.size(), 100 * within);
  EXPECT_GE(within, 0.9);

  // The road: the depth of the band just above the bonnet (the rows
  // kMaskRows..2 kMaskRows from the bottom), back-projected along cam0's rays:
  // in base_link (the mount) it must lie at z = -axle height, in odom (the
  // bag's poses and rig_tf's camera frame) at z = 0, the drive's road.
  const fm::Rig rig = fm::loadKalibrRig(ex + "/camchain.yaml", ex + "/mount.yaml");
  const fm::RigCamera& cam0 = rig.cameras[rig.indexOf("cam0")];
  const std::vector<Eigen::Vector3f> rays = fm::pixelRays(cam0.model);
  std::vector<double> z_base, z_odom;
  for (const auto& [stamp, d] : band_depth) {
    const Eigen::Isometry3d T_odom_cam =
        tf2::transformToEigen(tf_camera.at(stamp));
    for (int v = d.rows - 2 * kMaskRows; v < d.rows - kMaskRows; ++v) {
      for (int u = 0; u < d.cols; ++u) {
        const float r = d.at<float>(v, u);
        const Eigen::Vector3f& ray = rays[std::size_t(v) * d.cols + u];
        if (!std::isfinite(r) || !ray.allFinite()) continue;
        const Eigen::Vector3d p_cam = (ray * r).cast<double>();
        z_base.push_back((cam0.T_base_cam * p_cam).z());
        z_odom.push_back((T_odom_cam * p_cam).z());
      }
    }
  }
  ASSERT_GT(z_base.size(), 1000u);
  const double road_base = quantile(z_base, 0.5), road_odom = quantile(z_odom, 0.5);
  std::printf("road above the bonnet: %zu depth pixels, median z %.3f m in base_link, %.3f m in odom\n", z_base.size(),
              road_base, road_odom);
  EXPECT_NEAR(road_base, -kAxle, 0.05);
  EXPECT_NEAR(road_odom, 0.0, 0.05);
  std::system(("rm -rf " + dir + " " + log).c_str());
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_own_rig");
  return RUN_ALL_TESTS();
}
