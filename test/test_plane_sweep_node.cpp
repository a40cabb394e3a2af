// rostest: the PlaneSweepDepth nodelet subscribes only while someone listens,
// turns rendered frame sets into depth with the reference image's header that
// matches the rendered truth, and skips bad frame sets without going down;
// depth/camera_info is the camchain's reference camera and depth/image_z is
// range * the z of each pixel's unit ray.
#include <cv_bridge/cv_bridge.h>
#include <dynamic_reconfigure/Reconfigure.h>
#include <gtest/gtest.h>
#include <ros/package.h>
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/eval/depth_error.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/sim/synthetic_world.h"
#include "ros_test_utils.h"

namespace fm = fisheye_mapping;

namespace {

using fisheye_mapping::test::waitFor;


}  // namespace

TEST(PlaneSweepDepthNode, LazyDepthWithTheReferenceHeaderMatchingTruth) {
  ros::NodeHandle nh;
  const std::string dir = ros::package::getPath("fisheye_mapping") + "/test/data/";
  const fm::Rig rig = fm::loadKalibrRig(dir + "small_rig_camchain.yaml", dir + "small_rig_mount.yaml");
  fm::synth::WorldConfig wc;
  wc.seed = 2;
  wc.route_length = 120;
  const fm::synth::World world(wc);
  const double t = 3.0;
  fisheye_mapping::CameraFrameSet set;
  set.header.stamp = ros::Time(1700000003, 250000000);
  set.header.frame_id = rig.cameras[0].frame_id;
  cv::Mat truth;
  for (size_t c = 0; c < rig.cameras.size(); ++c) {
    const auto& cam = rig.cameras[c];
    auto frame = world.render(cam.model, fm::pixelRays(cam.model), world.egoPose(t) * cam.T_base_cam, t, 100 + c);
    if (c == 0) truth = frame.depth;
    std_msgs::Header h;
    h.stamp = set.header.stamp;
    h.frame_id = cam.frame_id;
    set.camera_names.push_back(cam.name);
    set.images.push_back(*cv_bridge::CvImage(h, "mono8", frame.image).toImageMsg());
  }

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
  dynamic_reconfigure::Reconfigure srv;
  dynamic_reconfigure::DoubleParameter ratio;
  ratio.name = "max_ratio";
  ratio.value = 0.5;
  srv.request.config.doubles.push_back(ratio);
  ASSERT_TRUE(ros::service::waitForService("plane_sweep/set_parameters", ros::Duration(10.0)));
  ASSERT_TRUE(ros::service::call("plane_sweep/set_parameters", srv));
  const int before = cv::countNonZero(d == d);  // d: the first depth's (its message held by `first`)
  fisheye_mapping::CameraFrameSet strict = set;
  strict.header.stamp += ros::Duration(1.0);
  for (auto& img : strict.images) img.header.stamp = strict.header.stamp;
  pub.publish(strict);
  ASSERT_TRUE(waitFor([&] { return depth->header.stamp == strict.header.stamp; }, 60.0)) << "no depth after reconfigure";
  const int after = cv::countNonZero(cv_bridge::toCvShare(depth)->image == cv_bridge::toCvShare(depth)->image);
  EXPECT_LT(after, before * 0.9) << "max_ratio 0.5 kept " << after << " of " << before << " pixels";
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_plane_sweep_node");
  ros::AsyncSpinner spinner(1);
  spinner.start();
  return RUN_ALL_TESTS();
}
