// rostest: the PlaneSweepDepth nodelet subscribes only while someone listens,
// turns rendered frame sets into depth with the reference image's header that
// matches the rendered truth, and skips bad frame sets without going down.
#include <cv_bridge/cv_bridge.h>
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

  sensor_msgs::ImageConstPtr depth, cost, uniq;
  auto sub_d = nh.subscribe<sensor_msgs::Image>("depth", 5, [&](const sensor_msgs::ImageConstPtr& m) { depth = m; });
  auto sub_c = nh.subscribe<sensor_msgs::Image>("cost", 5, [&](const sensor_msgs::ImageConstPtr& m) { cost = m; });
  auto sub_u = nh.subscribe<sensor_msgs::Image>("uniqueness", 5, [&](const sensor_msgs::ImageConstPtr& m) { uniq = m; });
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
  ASSERT_TRUE(waitFor([&] { return depth && cost && uniq; }, 60.0)) << "no depth: the nodelet did not survive the bad frame sets";
  EXPECT_EQ(depth->header.stamp, set.header.stamp);
  EXPECT_EQ(depth->header.frame_id, rig.cameras[0].frame_id);
  EXPECT_EQ(cost->header.stamp, set.header.stamp);
  EXPECT_EQ(uniq->header.frame_id, rig.cameras[0].frame_id);
  EXPECT_EQ(depth->encoding, sensor_msgs::image_encodings::TYPE_32FC1);
  ASSERT_EQ(depth->width, 256u);
  ASSERT_EQ(depth->height, 136u);
  const cv::Mat d = cv_bridge::toCvShare(depth)->image;
  // Filtered depth (paper defaults) of quarter-resolution images: sparse but
  // right where present.
  const fm::DepthErrorStats e = fm::depthError(d, truth, cv::Mat(), 15.0, 60.0);
  EXPECT_GT(e.valid, 1000u);
  EXPECT_LT(e.median, 0.2) << "median error " << e.median;  // 130 px focal length, 0.3 m baselines
  // The cost image agrees with the filter: every depth kept has cost <= 0.3.
  const cv::Mat c = cv_bridge::toCvShare(cost)->image;
  for (int v = 0; v < d.rows; ++v) {
    for (int u = 0; u < d.cols; ++u) {
      if (std::isfinite(d.at<float>(v, u))) ASSERT_LE(c.at<float>(v, u), 0.3f);
    }
  }
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_plane_sweep_node");
  ros::AsyncSpinner spinner(1);
  spinner.start();
  return RUN_ALL_TESTS();
}
