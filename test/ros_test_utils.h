// Shared by the rostest nodes.
#ifndef FISHEYE_MAPPING_TEST_ROS_TEST_UTILS_H_
#define FISHEYE_MAPPING_TEST_ROS_TEST_UTILS_H_

#include <ros/ros.h>

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

}  // namespace test
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_TEST_ROS_TEST_UTILS_H_
