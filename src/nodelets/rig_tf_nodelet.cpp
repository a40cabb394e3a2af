// Publishes the rig's static mounts (base_link -> each camera's optical frame)
// on /tf_static, from the calibration files named by ~camchain and ~mount.
// For logged drives whose bags lack /tf_static, and for live rigs.
// Any error (a malformed calibration, a failed publish) is logged and reported
// on /diagnostics (StageMonitor "rig_tf": ERROR naming the error,
// "mounts published", "base frame"; input = the calibration read, output = the
// mounts sent); the nodelet stays loaded so that the manager and its other
// nodelets keep running.
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <geometry_msgs/TransformStamped.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <tf2_ros/static_transform_broadcaster.h>

#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/node_options.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_monitor.h"

namespace fisheye_mapping {

class RigTfNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    try {
      monitor_ = std::make_unique<StageMonitor>(getNodeHandle(), getPrivateNodeHandle(), "rig_tf");
      monitor_->setInputExpected(false);  // one calibration at start-up, then silence
      monitor_->setExtraReport([this](diagnostic_updater::DiagnosticStatusWrapper& stat) { report(stat); });
    } catch (const std::exception& e) {
      NODELET_ERROR("no diagnostics: %s", e.what());
    }
    try {
      publishMounts();
    } catch (const std::exception& e) {
      fail(e.what());
    } catch (...) {
      fail("unknown exception");
    }
  }

  // Stay loaded (the manager and its other nodelets keep running), say why.
  void fail(const std::string& what) {
    std::lock_guard<std::mutex> lock(mutex_);
    error_ = what;
    if (monitor_) monitor_->error(what);
    NODELET_ERROR("rig calibration not loaded, no transforms published: %s", what.c_str());
  }

  void publishMounts() {
    if (monitor_) monitor_->input();
    requireKnownParams(getPrivateNodeHandle(), {RigTfNodeOptions::params().names()});
    const Rig rig = loadRigFromParams(getPrivateNodeHandle());
    std::vector<geometry_msgs::TransformStamped> transforms;
    const ros::Time stamp = ros::Time::now();
    for (const RigCamera& cam : rig.cameras) {
      transforms.push_back(toTransformMsg(cam.T_base_cam, rig.base_frame, cam.frame_id, stamp));
    }
    broadcaster_ = std::make_unique<tf2_ros::StaticTransformBroadcaster>();
    broadcaster_->sendTransform(transforms);
    std::lock_guard<std::mutex> lock(mutex_);
    published_ = transforms.size();
    base_frame_ = rig.base_frame;
    if (monitor_) monitor_->output();
    NODELET_INFO("published %zu static camera mounts relative to '%s'", transforms.size(), rig.base_frame.c_str());
  }

  void report(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!error_.empty()) stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::ERROR, "no mounts published: " + error_);
    stat.add("mounts published", published_);
    if (!base_frame_.empty()) stat.add("base frame", base_frame_);
  }

  std::unique_ptr<tf2_ros::StaticTransformBroadcaster> broadcaster_;
  std::size_t published_ = 0;
  std::string base_frame_, error_;
  std::mutex mutex_;
  std::unique_ptr<StageMonitor> monitor_;
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::RigTfNodelet, nodelet::Nodelet)
