// Publishes the rig's static mounts (base_link -> each camera's optical frame)
// on /tf_static, from the calibration files named by ~camchain and ~mount.
// For logged drives whose bags lack /tf_static, and for live rigs.
#include <vector>

#include <geometry_msgs/TransformStamped.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include "fisheye_mapping/ros/ros_params.h"

namespace fisheye_mapping {

class RigTfPublisherNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    Rig rig;
    try {
      rig = loadRigFromParams(getPrivateNodeHandle());
    } catch (const CalibrationError& e) {
      // Stay loaded (the manager and its other nodelets keep running), say why.
      NODELET_ERROR("rig calibration not loaded, no transforms published: %s", e.what());
      return;
    }
    std::vector<geometry_msgs::TransformStamped> transforms;
    const ros::Time stamp = ros::Time::now();
    for (const RigCamera& cam : rig.cameras) {
      geometry_msgs::TransformStamped t = tf2::eigenToTransform(cam.T_base_cam);
      t.header.stamp = stamp;
      t.header.frame_id = rig.base_frame;
      t.child_frame_id = cam.frame_id;
      transforms.push_back(t);
    }
    broadcaster_.sendTransform(transforms);
    NODELET_INFO("published %zu static camera mounts relative to '%s'", transforms.size(),
                 rig.base_frame.c_str());
  }

  tf2_ros::StaticTransformBroadcaster broadcaster_;
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::RigTfPublisherNodelet, nodelet::Nodelet)
