// Shared by the rostest nodes.
#ifndef FISHEYE_MAPPING_TEST_ROS_TEST_UTILS_H_
#define FISHEYE_MAPPING_TEST_ROS_TEST_UTILS_H_

#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <tf2_msgs/TFMessage.h>

#include <functional>

namespace fisheye_mapping {
namespace test {

// Polls `done` every 20 ms of wall time until it holds or `seconds` pass.
inline bool waitFor(const std::function<bool()>& done, double seconds) {
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(seconds);
  while (ros::ok() && ros::WallTime::now() < end) {
    if (done()) return true;
    ros::WallDuration(0.02).sleep();
  }
  return done();
}

// What tf2_ros::TransformBroadcaster does (a TFMessage on /tf), with the
// count of the nodes listening: a test waits until the node under test has
// connected before the first pose, which tf would otherwise drop unseen (the
// node's first frame then never gets its pose).
class TfPublisher {
 public:
  TfPublisher() : pub_(ros::NodeHandle().advertise<tf2_msgs::TFMessage>("/tf", 100)) {}
  void sendTransform(const geometry_msgs::TransformStamped& t) {
    tf2_msgs::TFMessage m;
    m.transforms.push_back(t);
    pub_.publish(m);
  }
  uint32_t getNumSubscribers() const { return pub_.getNumSubscribers(); }

 private:
  ros::Publisher pub_;
};

}  // namespace test
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_TEST_ROS_TEST_UTILS_H_
