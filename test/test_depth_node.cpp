// rostest: the Depth nodelet subscribes only while someone listens,
// turns rendered frame sets into depth with the reference image's header that
// matches the rendered truth, and skips bad frame sets without going down;
// depth/camera_info is the camchain's reference camera and depth/image_z is
// range * the z of each pixel's unit ray; with ~rig_source camera_info the
// rig comes from the sets' CameraInfos and tf, and the depth is the same.
#include <cv_bridge/cv_bridge.h>
#include <dynamic_reconfigure/Reconfigure.h>
#include <gtest/gtest.h>
#include <unistd.h>
#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <mutex>
#include <ros/package.h>
#include <ros/ros.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_broadcaster.h>
#include <pcl_conversions/pcl_conversions.h>
#include <sensor_msgs/PointCloud2.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/FilePath.h"
#include "fisheye_mapping/FrameDone.h"
#include "fisheye_mapping/RigSelfCalibration.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/eval/depth_error.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/sim/synthetic_world.h"
#include "ros_test_utils.h"
#include "small_rig_frames.h"

namespace fm = fisheye_mapping;

namespace {

using fisheye_mapping::test::renderedSet;
using fisheye_mapping::test::smallRig;
using fisheye_mapping::test::smallRigInfo;
using fisheye_mapping::test::waitFor;

void setMaxRatio(const std::string& node, double value) {
  dynamic_reconfigure::Reconfigure srv;
  dynamic_reconfigure::DoubleParameter ratio;
  ratio.name = "max_ratio";
  ratio.value = value;
  srv.request.config.doubles.push_back(ratio);
  ASSERT_TRUE(ros::service::waitForService(node + "/set_parameters", ros::Duration(10.0)));
  ASSERT_TRUE(ros::service::call(node + "/set_parameters", srv));
}

}  // namespace

TEST(PlaneSweepDepthNode, LazyDepthWithTheReferenceHeaderMatchingTruth) {
  ros::NodeHandle nh;
  const fm::Rig rig = smallRig();
  cv::Mat truth;
  const fisheye_mapping::CameraFrameSet set = renderedSet(rig, &truth);

  ros::Publisher pub = nh.advertise<fisheye_mapping::CameraFrameSet>("frames", 5);
  // Lazy: nobody listens to depth yet, so the nodelet has not subscribed.
  ros::WallDuration(1.0).sleep();
  EXPECT_EQ(pub.getNumSubscribers(), 0u);

  sensor_msgs::ImageConstPtr depth, cost, uniq, zdepth;
  sensor_msgs::CameraInfoConstPtr info;
  auto sub_i = nh.subscribe<sensor_msgs::CameraInfo>("depth/camera_info", 5, [&](const sensor_msgs::CameraInfoConstPtr& m) { info = m; });
  auto sub_z = nh.subscribe<sensor_msgs::Image>("depth/image_z", 5, [&](const sensor_msgs::ImageConstPtr& m) { zdepth = m; });
  auto sub_d = nh.subscribe<sensor_msgs::Image>("depth/image", 5, [&](const sensor_msgs::ImageConstPtr& m) { depth = m; });
  auto sub_c = nh.subscribe<sensor_msgs::Image>("depth/cost", 5, [&](const sensor_msgs::ImageConstPtr& m) { cost = m; });
  auto sub_u = nh.subscribe<sensor_msgs::Image>("depth/uniqueness", 5, [&](const sensor_msgs::ImageConstPtr& m) { uniq = m; });
  ASSERT_TRUE(waitFor([&] { return pub.getNumSubscribers() == 1; }, 20.0)) << "the nodelet never subscribed";

  // A bad frame set first: wrong encoding on a supporting camera.
  fisheye_mapping::CameraFrameSet bad = set;
  bad.images[1].encoding = "16SC1";
  pub.publish(bad);
  // Then one without the reference camera.
  fisheye_mapping::CameraFrameSet noref = set;
  noref.camera_names[0] = "camX";
  pub.publish(noref);
  ros::WallDuration(0.5).sleep();
  EXPECT_FALSE(depth) << "a bad frame set produced depth";

  pub.publish(set);
  ASSERT_TRUE(waitFor([&] { return depth && cost && uniq && info && zdepth; }, 60.0)) << "no depth: the nodelet did not survive the bad frame sets";
  EXPECT_EQ(depth->header.stamp, set.header.stamp);
  EXPECT_EQ(depth->header.frame_id, rig.cameras[0].frame_id);
  EXPECT_EQ(cost->header.stamp, set.header.stamp);
  EXPECT_EQ(uniq->header.frame_id, rig.cameras[0].frame_id);
  EXPECT_EQ(depth->encoding, sensor_msgs::image_encodings::TYPE_32FC1);
  ASSERT_EQ(depth->width, 256u);
  ASSERT_EQ(depth->height, 136u);
  const sensor_msgs::ImageConstPtr first = depth;  // keeps d's data
  const cv::Mat d = cv_bridge::toCvShare(first)->image;
  // Filtered depth (paper defaults) of quarter-resolution images: sparse but
  // right where present.
  const fm::DepthErrorStats e = fm::depthError(d, truth, cv::Mat(), 15.0, 60.0);
  EXPECT_GT(e.valid, 1000u);
  EXPECT_LT(e.median, 0.2) << "median error " << e.median;  // 130 px focal length, 0.3 m baselines
  // depth/camera_info: the depth image's header and the camchain's cam0
  // (test/data/small_rig_camchain.yaml: omni [0.98, 130, 130, 127.5, 67.5],
  // radtan [-0.02, 0.004, 0.0002, -0.0001], 256 x 136).
  EXPECT_EQ(info->header.stamp, depth->header.stamp);
  EXPECT_EQ(info->header.frame_id, depth->header.frame_id);
  EXPECT_EQ(info->width, 256u);
  EXPECT_EQ(info->height, 136u);
  EXPECT_EQ(info->distortion_model, "omni");
  const std::vector<double> K{130.0, 0.0, 127.5, 0.0, 130.0, 67.5, 0.0, 0.0, 1.0};
  for (int k = 0; k < 9; ++k) EXPECT_DOUBLE_EQ(info->K[k], K[k]) << k;
  EXPECT_EQ(info->D, (std::vector<double>{0.98, -0.02, 0.004, 0.0002, -0.0001}));
  // depth/image_z: z = range * ray.z, the ray unprojected here by the core model.
  ASSERT_EQ(zdepth->header.stamp, depth->header.stamp);
  const cv::Mat z = cv_bridge::toCvShare(zdepth)->image;
  ASSERT_EQ(z.size(), d.size());
  int checked = 0;
  for (int v = 0; v < d.rows; ++v) {
    for (int u = 0; u < d.cols; ++u) {
      const float r = d.at<float>(v, u);
      Eigen::Vector3d ray;
      if (!std::isfinite(r) || !rig.cameras[0].model.unproject(Eigen::Vector2d(u, v), &ray) || ray.z() <= 0) continue;
      ASSERT_NEAR(z.at<float>(v, u), r * ray.normalized().z(), 1e-4 * r) << u << "," << v;
      ++checked;
    }
  }
  EXPECT_GT(checked, 1000);
  // The cost image agrees with the filter: every depth kept has cost <= 0.3.
  const cv::Mat c = cv_bridge::toCvShare(cost)->image;
  for (int v = 0; v < d.rows; ++v) {
    for (int u = 0; u < d.cols; ++u) {
      if (std::isfinite(d.at<float>(v, u))) ASSERT_LE(c.at<float>(v, u), 0.3f);
    }
  }
  // dynamic_reconfigure: a stricter uniqueness ratio keeps fewer pixels.
  setMaxRatio("depth", 0.5);
  const int before = cv::countNonZero(d == d);  // d: the first depth's (its message held by `first`)
  fisheye_mapping::CameraFrameSet strict = set;
  strict.header.stamp += ros::Duration(1.0);
  for (auto& img : strict.images) img.header.stamp = strict.header.stamp;
  pub.publish(strict);
  ASSERT_TRUE(waitFor([&] { return depth->header.stamp == strict.header.stamp; }, 60.0)) << "no depth after reconfigure";
  const int after = cv::countNonZero(cv_bridge::toCvShare(depth)->image == cv_bridge::toCvShare(depth)->image);
  EXPECT_LT(after, before * 0.9) << "max_ratio 0.5 kept " << after << " of " << before << " pixels";
}

// ~rig_source camera_info (the "ci" node): frame sets before tf knows the
// camera frames are dropped as "no rig yet"; then the rig comes from the
// sets' CameraInfos and /tf_static, and the depth equals the camchain node's
// on the same set, pixel for pixel.
TEST(PlaneSweepDepthNode, RigFromCameraInfoGivesTheCamchainDepth) {
  ros::NodeHandle nh;
  const fm::Rig rig = smallRig();
  cv::Mat truth;
  fisheye_mapping::CameraFrameSet set = renderedSet(rig, &truth);
  set.header.stamp += ros::Duration(5.0);
  for (auto& img : set.images) img.header.stamp = set.header.stamp;
  fisheye_mapping::CameraFrameSet ci_set = set;
  for (const auto& img : set.images) ci_set.camera_infos.push_back(smallRigInfo(img.header));
  // Both nodes with the same filters (the first test made /depth's stricter).
  // The config's value (0.9) on both; reconfigured on the ci node before its
  // stage exists, so its stage must be built with it.
  setMaxRatio("depth", 0.9);
  setMaxRatio("ci/depth", 0.9);

  std::mutex m;
  std::map<std::string, std::string> diag;  // the ci node's depth status
  auto diag_sub = nh.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 20, [&](const diagnostic_msgs::DiagnosticArrayConstPtr& a) {
        std::lock_guard<std::mutex> lock(m);
        for (const auto& st : a->status) {
          if (st.name.find("ci/depth") == std::string::npos) continue;
          for (const auto& kv : st.values) diag[kv.key] = kv.value;
        }
      });
  auto diagValue = [&](const std::string& key) {
    std::lock_guard<std::mutex> lock(m);
    return diag.count(key) ? diag[key] : std::string();
  };
  sensor_msgs::ImageConstPtr depth, ci_depth;
  sensor_msgs::CameraInfoConstPtr ci_info;
  auto sub_d = nh.subscribe<sensor_msgs::Image>("depth/image", 5, [&](const sensor_msgs::ImageConstPtr& d) {
    std::lock_guard<std::mutex> lock(m);
    depth = d;
  });
  auto sub_ci = nh.subscribe<sensor_msgs::Image>("ci/depth/image", 5, [&](const sensor_msgs::ImageConstPtr& d) {
    std::lock_guard<std::mutex> lock(m);
    ci_depth = d;
  });
  auto sub_info = nh.subscribe<sensor_msgs::CameraInfo>("ci/depth/camera_info", 5,
                                                        [&](const sensor_msgs::CameraInfoConstPtr& i) { ci_info = i; });
  ros::Publisher pub = nh.advertise<fisheye_mapping::CameraFrameSet>("frames", 5);
  ros::Publisher ci_pub = nh.advertise<fisheye_mapping::CameraFrameSet>("ci/frames", 5);
  ASSERT_TRUE(waitFor([&] { return pub.getNumSubscribers() == 1 && ci_pub.getNumSubscribers() == 1; }, 20.0));

  // No tf yet: dropped, counted and no depth.
  ci_pub.publish(ci_set);
  ASSERT_TRUE(waitFor([&] { return !diagValue("dropped: no rig yet").empty(); }, 10.0))
      << "inputs '" << diagValue("inputs") << "'";
  EXPECT_NE(diagValue("dropped: no rig yet").find(", 1 total"), std::string::npos) << diagValue("dropped: no rig yet");
  EXPECT_NE(diagValue("last tf failure").find("no transform from 'cam0_optical_frame' to 'base_link'"),
            std::string::npos)
      << diagValue("last tf failure");
  EXPECT_FALSE(ci_depth);

  // The mount on /tf_static, as robot_state_publisher or the rig tf publisher gives it.
  tf2_ros::StaticTransformBroadcaster static_tf;
  static_tf.sendTransform(fm::test::mountTransforms(rig, set.header.stamp));
  ros::WallDuration(0.5).sleep();
  pub.publish(set);
  ci_pub.publish(ci_set);
  ASSERT_TRUE(waitFor([&] {
    std::lock_guard<std::mutex> lock(m);
    return depth && ci_depth && depth->header.stamp == set.header.stamp && ci_depth->header.stamp == set.header.stamp;
  }, 90.0)) << "no depth from both nodes";
  EXPECT_EQ(ci_depth->header.frame_id, rig.cameras[0].frame_id);
  const cv::Mat a = cv_bridge::toCvShare(depth)->image, b = cv_bridge::toCvShare(ci_depth)->image;
  ASSERT_EQ(a.size(), b.size());
  int valid = 0, mismatched = 0;
  for (int v = 0; v < a.rows; ++v) {
    for (int u = 0; u < a.cols; ++u) {
      const float x = a.at<float>(v, u), y = b.at<float>(v, u);
      if (std::isfinite(x) != std::isfinite(y)) {
        ++mismatched;
        continue;
      }
      if (!std::isfinite(x)) continue;
      ++valid;
      ASSERT_NEAR(x, y, 1e-4) << u << "," << v;
    }
  }
  EXPECT_GT(valid, 1000);
  EXPECT_EQ(mismatched, 0) << "pixels valid in one depth image only";
  // Its depth/camera_info is the reference camera's CameraInfo it was given.
  ASSERT_TRUE(waitFor([&] { return ci_info && ci_info->header.stamp == set.header.stamp; }, 5.0));
  EXPECT_EQ(ci_info->D, ci_set.camera_infos[0].D);
  EXPECT_EQ(ci_info->K, ci_set.camera_infos[0].K);
  EXPECT_EQ(ci_info->distortion_model, "omni");
}

// No camchain anywhere (the "e2e" group): the sync builds the rig from the
// cameras' CameraInfos and /tf_static and sends them in each frame set, the
// depth stage builds its own from those, and the TSDF takes the model from
// depth/camera_info. The depth equals the camchain node's on the same images,
// and the map's surface points lie at the measured ranges.
TEST(PlaneSweepDepthNode, CameraInfoChainFromImagesToMap) {
  ros::NodeHandle nh;
  const fm::Rig rig = smallRig();
  cv::Mat truth;
  const fisheye_mapping::CameraFrameSet set = renderedSet(rig, &truth);
  setMaxRatio("depth", 0.9);
  setMaxRatio("e2e/depth", 0.9);
  tf2_ros::StaticTransformBroadcaster static_tf;
  tf2_ros::TransformBroadcaster tf;
  std::vector<ros::Publisher> image_pubs, info_pubs;
  for (size_t c = 0; c < rig.cameras.size(); ++c) {
    const auto& cam = rig.cameras[c];
    const std::string ns = "/e2e/" + cam.name;
    image_pubs.push_back(nh.advertise<sensor_msgs::Image>(ns + "/image_raw", 5));
    info_pubs.push_back(nh.advertise<sensor_msgs::CameraInfo>(ns + "/camera_info", 1, true));  // latched, as drivers do
    info_pubs.back().publish(smallRigInfo(set.images[c].header));
  }
  static_tf.sendTransform(fm::test::mountTransforms(rig, set.header.stamp));

  std::mutex m;
  sensor_msgs::ImageConstPtr depth, e2e_depth;
  sensor_msgs::PointCloud2ConstPtr cloud;
  int fused = 0;
  auto sub_d = nh.subscribe<sensor_msgs::Image>("depth/image", 5, [&](const sensor_msgs::ImageConstPtr& d) {
    std::lock_guard<std::mutex> lock(m);
    depth = d;
  });
  auto sub_e = nh.subscribe<sensor_msgs::Image>("e2e/depth/image", 5, [&](const sensor_msgs::ImageConstPtr& d) {
    std::lock_guard<std::mutex> lock(m);
    if (!e2e_depth) e2e_depth = d;
  });
  auto sub_c = nh.subscribe<sensor_msgs::PointCloud2>("e2e/tsdf/cloud", 2, [&](const sensor_msgs::PointCloud2ConstPtr& c) {
    std::lock_guard<std::mutex> lock(m);
    cloud = c;
  });
  auto sub_f = nh.subscribe<fisheye_mapping::FrameDone>("e2e/tsdf/fusion_done", 20,
                                                        [&](const fisheye_mapping::FrameDoneConstPtr& d) {
                                                          std::lock_guard<std::mutex> lock(m);
                                                          fused += d->fused;
                                                        });
  ros::Publisher pub = nh.advertise<fisheye_mapping::CameraFrameSet>("frames", 5);
  ASSERT_TRUE(waitFor([&] { return image_pubs[0].getNumSubscribers() > 0 && pub.getNumSubscribers() > 0; }, 30.0))
      << "subscribers: " << image_pubs[0].getNumSubscribers() << " of the e2e images (the sync), "
      << pub.getNumSubscribers() << " of frames (the camchain depth node)";

  // The vehicle standing where the images were rendered (synthetic_world's
  // ego pose at t = 3 s), frames 0.1 s apart until the map holds surface
  // points (the sync drops images until its rig is built; min_observations 3).
  const Eigen::Isometry3d T_W_B = fm::synth::World(fm::test::smallRigWorld()).egoPose(3.0);
  const ros::Time t0 = set.header.stamp + ros::Duration(20.0);
  bool mapped = false;
  for (int k = 0; k < 100 && !mapped; ++k) {
    const ros::Time stamp = t0 + ros::Duration(0.1 * k);
    geometry_msgs::TransformStamped t = tf2::eigenToTransform(T_W_B);
    t.header.stamp = stamp;
    t.header.frame_id = "map";
    t.child_frame_id = "base_link";
    tf.sendTransform(t);
    for (size_t c = 0; c < image_pubs.size(); ++c) {
      sensor_msgs::Image img = set.images[c];
      img.header.stamp = stamp;
      image_pubs[c].publish(img);
    }
    mapped = waitFor([&] {
      std::lock_guard<std::mutex> lock(m);
      return fused >= 3 && cloud && cloud->width * cloud->height > 1000;
    }, 1.0);
  }
  ASSERT_TRUE(mapped) << "no map from the camera_info chain (" << fused << " frames fused)";

  // Its first depth against the camchain node's on the same images and stamp.
  sensor_msgs::ImageConstPtr e2e;
  {
    std::lock_guard<std::mutex> lock(m);
    e2e = e2e_depth;
  }
  ASSERT_TRUE(e2e);
  EXPECT_EQ(e2e->header.frame_id, rig.cameras[0].frame_id);
  fisheye_mapping::CameraFrameSet same = set;
  same.header.stamp = e2e->header.stamp;
  for (auto& img : same.images) img.header.stamp = same.header.stamp;
  pub.publish(same);
  ASSERT_TRUE(waitFor([&] {
    std::lock_guard<std::mutex> lock(m);
    return depth && depth->header.stamp == same.header.stamp;
  }, 60.0));
  const cv::Mat a = cv_bridge::toCvShare(depth)->image, b = cv_bridge::toCvShare(e2e)->image;
  ASSERT_EQ(a.size(), b.size());
  int valid = 0, mismatched = 0;
  for (int v = 0; v < a.rows; ++v) {
    for (int u = 0; u < a.cols; ++u) {
      const float x = a.at<float>(v, u), y = b.at<float>(v, u);
      if (std::isfinite(x) != std::isfinite(y)) ++mismatched;
      if (!std::isfinite(x) || !std::isfinite(y)) continue;
      ++valid;
      ASSERT_NEAR(x, y, 1e-4) << u << "," << v;
    }
  }
  EXPECT_GT(valid, 1000);
  EXPECT_EQ(mismatched, 0);

  // The map: each surface point seen by cam0 lies on the ray of its pixel at
  // the range the depth stage measured there (the TSDF placed the depth with
  // the model of depth/camera_info; a wrong model would move the points).
  std::lock_guard<std::mutex> lock(m);
  EXPECT_EQ(cloud->header.frame_id, "map");
  pcl::PointCloud<pcl::PointXYZ> points;
  pcl::fromROSMsg(*cloud, points);
  const Eigen::Isometry3d T_C_W = (T_W_B * rig.cameras[0].T_base_cam).inverse();
  std::vector<double> errors;  // relative: |range of the point - measured range| / measured range
  for (const auto& p : points) {
    const Eigen::Vector3d q = T_C_W * Eigen::Vector3d(p.x, p.y, p.z);
    Eigen::Vector2d px;
    if (!rig.cameras[0].model.project(q, &px)) continue;
    const int u = int(std::lround(px.x())), v = int(std::lround(px.y()));
    if (u < 0 || v < 0 || u >= b.cols || v >= b.rows) continue;
    const float measured = b.at<float>(v, u);
    if (std::isfinite(measured)) errors.push_back(std::abs(q.norm() - measured) / measured);
  }
  ASSERT_GT(errors.size(), 500u) << "of " << points.size() << " map points";
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  EXPECT_LT(errors[errors.size() / 2], 0.02) << "median relative range error of " << errors.size() << " map points";
}

// The online self-calibration's state (depth/self_calibration, latched, after
// the frame sets of the tests above) and ~save_calibration: the camchain and
// its mount written, loadable, the old one kept as .1; a folder refused with
// a message naming it, the node going on.
TEST(PlaneSweepDepthNode, SelfCalibrationStateAndSaveService) {
  ros::NodeHandle nh;
  fisheye_mapping::RigSelfCalibrationConstPtr state;
  auto sub = nh.subscribe<fisheye_mapping::RigSelfCalibration>(
      "depth/self_calibration", 1, [&](const fisheye_mapping::RigSelfCalibrationConstPtr& m) { state = m; });
  ASSERT_TRUE(waitFor([&] { return state && state->updates > 0; }, 20.0)) << "no self-calibration state";
  EXPECT_EQ(state->reference_camera, "cam0");
  EXPECT_GE(state->frame_sets, state->updates);
  ASSERT_EQ(state->cameras.size(), 3u);
  EXPECT_TRUE(state->cameras[0].reference);
  const fm::Rig rig = smallRig();
  for (int c = 1; c < 3; ++c) {
    const auto& cam = state->cameras[c];
    EXPECT_EQ(cam.camera, rig.cameras[c].name);
    EXPECT_FALSE(cam.reference);
    EXPECT_FALSE(cam.status.empty());
    // The rig is exact: whatever the evidence, no correction beyond the noise.
    EXPECT_LT(cam.correction_deg, 0.1) << cam.status;
    // The same images again and again (the car stands): no translation
    // evidence, none applied.
    EXPECT_EQ(cam.translation_updates, 0) << cam.translation_status;
    for (int a = 0; a < 3; ++a) EXPECT_EQ(cam.translation_correction_mm[a], 0.0);
  }
  // Inside the save folder ($ROS_HOME/fisheye_mapping): a relative path.
  const char* ros_home = std::getenv("ROS_HOME");
  const std::filesystem::path folder =
      std::filesystem::path(ros_home && *ros_home ? ros_home : std::string(std::getenv("HOME")) + "/.ros") /
      "fisheye_mapping";
  const std::string subfolder = "fm_test_depth_node_" + std::to_string(getpid());
  fisheye_mapping::FilePath srv;
  srv.request.path = subfolder + "/camchain.yaml";
  ASSERT_TRUE(ros::service::waitForService("depth/save_calibration", ros::Duration(10.0)));
  for (int k = 0; k < 2; ++k) {
    ASSERT_TRUE(ros::service::call("depth/save_calibration", srv));
    EXPECT_TRUE(srv.response.success) << srv.response.message;
  }
  const std::string dir = std::filesystem::canonical(folder / subfolder).string();
  EXPECT_NE(srv.response.message.find(dir + "/camchain.yaml"), std::string::npos) << srv.response.message;
  EXPECT_TRUE(std::filesystem::exists(dir + "/camchain.yaml.1"));
  const fm::Rig saved = fm::loadKalibrRig(dir + "/camchain.yaml", dir + "/camchain_mount.yaml");
  ASSERT_EQ(saved.cameras.size(), 3u);
  for (int c = 0; c < 3; ++c) {
    EXPECT_LT((saved.cameras[c].T_cam0_cam.translation() - rig.cameras[c].T_cam0_cam.translation()).norm(), 1e-9);
    EXPECT_LT(Eigen::AngleAxisd(saved.cameras[c].T_cam0_cam.linear().transpose() * rig.cameras[c].T_cam0_cam.linear())
                  .angle() * 180 / M_PI, state->cameras[c].correction_deg + 1e-6);
  }
  srv.request.path = dir;
  ASSERT_TRUE(ros::service::call("depth/save_calibration", srv));
  EXPECT_FALSE(srv.response.success);
  EXPECT_NE(srv.response.message.find(dir), std::string::npos) << srv.response.message;
  // Outside the save folder: refused naming it, nothing written there.
  const std::string outside = "/tmp/fm_test_plane_sweep_outside_" + std::to_string(getpid()) + ".yaml";
  srv.request.path = outside;
  ASSERT_TRUE(ros::service::call("depth/save_calibration", srv));
  EXPECT_FALSE(srv.response.success);
  EXPECT_NE(srv.response.message.find("outside the save folder " + std::filesystem::canonical(folder).string()),
            std::string::npos)
      << srv.response.message;
  EXPECT_FALSE(std::filesystem::exists(outside));
  std::filesystem::remove_all(dir);
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_depth_node");
  ros::AsyncSpinner spinner(1);
  spinner.start();
  return RUN_ALL_TESTS();
}
