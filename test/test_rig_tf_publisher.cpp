// rostest: the RigTf nodelet, loaded into a nodelet manager through
// pluginlib, publishes the rig's mounts on /tf_static; a second instance with a
// malformed calibration does not bring the manager down.
#include <gtest/gtest.h>
#include <nodelet/NodeletList.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

namespace {

TEST(RigTf, PublishesTheMountsOfTheRig) {
  tf2_ros::Buffer buffer;
  tf2_ros::TransformListener listener(buffer);
  std::string error;
  ASSERT_TRUE(buffer.canTransform("base_link", "cam1_optical", ros::Time(0), ros::Duration(30.0), &error))
      << error;
  const auto t0 = buffer.lookupTransform("base_link", "cam0_optical", ros::Time(0));
  const auto t1 = buffer.lookupTransform("base_link", "cam1_optical", ros::Time(0));
  // test/data/two_camera_mount.yaml: cam0 at (1.5, 0, 1.6) in base_link.
  EXPECT_NEAR(t0.transform.translation.x, 1.5, 1e-9);
  EXPECT_NEAR(t0.transform.translation.y, 0.0, 1e-9);
  EXPECT_NEAR(t0.transform.translation.z, 1.6, 1e-9);
  // cam1 is 0.5 m along cam0's +x (its right), i.e. base_link's -y.
  EXPECT_NEAR(t1.transform.translation.x, 1.5, 1e-9);
  EXPECT_NEAR(t1.transform.translation.y, -0.5, 1e-9);
  EXPECT_NEAR(t1.transform.translation.z, 1.6, 1e-9);
  // Optical frame (z forward, x right, y down) in base_link (x forward, y left,
  // z up): the standard quaternion (x, y, z, w) = +-(-0.5, 0.5, -0.5, 0.5).
  const auto& q = t1.transform.rotation;
  const double sign = q.w >= 0 ? 1.0 : -1.0;
  EXPECT_NEAR(sign * q.x, -0.5, 1e-9);
  EXPECT_NEAR(sign * q.y, 0.5, 1e-9);
  EXPECT_NEAR(sign * q.z, -0.5, 1e-9);
  EXPECT_NEAR(sign * q.w, 0.5, 1e-9);
  EXPECT_EQ(t1.header.frame_id, "base_link");
}

TEST(RigTf, BadCalibrationLeavesTheManagerRunning) {
  ASSERT_TRUE(ros::service::waitForService("/manager/list", ros::Duration(30.0)));
  // Both instances were loaded (loading waits for onInit), the bad one too.
  nodelet::NodeletList list;
  for (int i = 0; i < 100; ++i) {
    ASSERT_TRUE(ros::service::call("/manager/list", list));
    if (list.response.nodelets.size() >= 2) break;
    ros::Duration(0.1).sleep();
  }
  std::vector<std::string> names = list.response.nodelets;
  std::sort(names.begin(), names.end());
  ASSERT_EQ(names.size(), 2u);
  EXPECT_EQ(names[0], "/rig_tf");
  EXPECT_EQ(names[1], "/rig_tf_bad");
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_rig_tf_publisher");
  ros::NodeHandle nh;
  return RUN_ALL_TESTS();
}
