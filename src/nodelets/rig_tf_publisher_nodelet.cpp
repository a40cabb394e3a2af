// Publishes the rig's static mounts (base_link -> each camera's optical frame)
// on /tf_static, from the calibration files named by ~camchain and ~mount.
// For logged drives whose bags lack /tf_static, and for live rigs.
// Any error (a malformed calibration, a failed publish) is logged and reported
// on /diagnostics (ERROR); the nodelet stays loaded so that the manager and its
// other nodelets keep running.
#include <memory>
#include <string>
#include <vector>

#include <diagnostic_updater/diagnostic_updater.h>
#include <geometry_msgs/TransformStamped.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <tf2_ros/static_transform_broadcaster.h>

#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_health.h"

namespace fisheye_mapping {

class RigTfPublisherNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    try {
      publishMounts();
    } catch (const std::exception& e) {
      // Stay loaded (the manager and its other nodelets keep running), say why.
      error_ = e.what();
      health_.error(error_);
      NODELET_ERROR("rig calibration not loaded, no transforms published: %s", e.what());
    } catch (...) {
      error_ = "unknown exception";
      health_.error(error_);
      NODELET_ERROR("rig calibration not loaded, no transforms published: unknown exception");
    }
    try {
      diag_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, getName());
      diag_->setHardwareID("fisheye rig mounts");
      diag_->add("camera mounts", this, &RigTfPublisherNodelet::diagnose);
      diag_timer_ = nh.createWallTimer(ros::WallDuration(1.0), [this](const ros::WallTimerEvent&) {
        try {
          diag_->force_update();
        } catch (const std::exception& e) {
          NODELET_ERROR_THROTTLE(10.0, "diagnostics not published: %s", e.what());
        }
      });
    } catch (const std::exception& e) {
      NODELET_ERROR("no diagnostics: %s", e.what());
    }
  }

  void publishMounts() {
    const Rig rig = loadRigFromParams(getPrivateNodeHandle());
    std::vector<geometry_msgs::TransformStamped> transforms;
    const ros::Time stamp = ros::Time::now();
    for (const RigCamera& cam : rig.cameras) {
      transforms.push_back(toTransformMsg(cam.T_base_cam, rig.base_frame, cam.frame_id, stamp));
    }
    broadcaster_ = std::make_unique<tf2_ros::StaticTransformBroadcaster>();
    broadcaster_->sendTransform(transforms);
    published_ = transforms.size();
    base_frame_ = rig.base_frame;
    NODELET_INFO("published %zu static camera mounts relative to '%s'", transforms.size(), rig.base_frame.c_str());
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    if (error_.empty()) {
      stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "mounts published on /tf_static");
    } else {
      stat.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "no mounts published: " + error_);
    }
    stat.add("mounts published", published_);
    if (!base_frame_.empty()) stat.add("base frame", base_frame_);
    health_.report(stat);
  }

  std::unique_ptr<tf2_ros::StaticTransformBroadcaster> broadcaster_;
  std::size_t published_ = 0;
  std::string base_frame_, error_;
  StageHealth health_;
  std::unique_ptr<diagnostic_updater::Updater> diag_;
  ros::WallTimer diag_timer_;
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::RigTfPublisherNodelet, nodelet::Nodelet)
