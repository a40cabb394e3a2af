// Frame-set sync nodelet: groups the rig's camera images into CameraFrameSets.
//
// Subscribes  one image topic per camera of the rig (the camchain's rostopic,
//             or ~image_topics: list in camera order), through image_transport
//             (~image_transport hint), only while `frames` has subscribers.
// Publishes   frames (fisheye_mapping/CameraFrameSet): header = the reference
//             (first) camera's image header; images in camera order.
//             /diagnostics: per-camera input rates, sets out, incomplete sets
//             dropped, out-of-order / bad images, latency, silent cameras,
//             time resets and callback errors (WARN for a while after one).
// Parameters  ~camchain, ~mount (the rig), ~policy (exact | approximate),
//             ~max_interval (s, approximate), ~queue_size (open sets),
//             ~silent_warning (s of ROS time - sim time under a bag - without
//             an image before a camera is reported), ~time_reset_threshold
//             (s, default 1; 0: never reset).
// Time going backwards (a bag played again, rosbag play restarted, a sim clock
// reset): an image older than its camera's newest by more than the threshold,
// or a ROS clock (sim time) behind the newest image by more than it, resets
// the sync (core FrameSetSync), with a warning naming both stamps.
// Any number of cameras (message_filters' Synchronizer stops at 9): the
// grouping is the core FrameSetSync. Images whose size differs from the
// calibration, malformed images and images in an encoding that is not a
// camera-image encoding of ros/conversions.h are reported and dropped.
#include <memory>
#include <mutex>

#include <diagnostic_updater/diagnostic_updater.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_health.h"

namespace fisheye_mapping {

class FrameSyncNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    pnh.param<std::string>("image_transport", transport_, "raw");
    try {
      // Every sync parameter is declared once, in the core (FrameSyncConfig).
      cfg_ = FrameSyncConfig::fromParams(RosParams(pnh));
      const FrameSyncConfig& cfg = cfg_;
      silent_s_ = cfg.silent_warning;
      rig_ = loadRigFromParams(pnh);
      topics_ = cfg.image_topics;
      if (topics_.empty()) {
        for (const auto& c : rig_.cameras) {
          if (c.rostopic.empty()) throw CalibrationError("camera " + c.name + " has no rostopic in the camchain; set ~image_topics");
          topics_.push_back(c.rostopic);
        }
      }
      if (topics_.size() != rig_.cameras.size())
        throw CalibrationError("~image_topics has " + std::to_string(topics_.size()) + " topics for " +
                               std::to_string(rig_.cameras.size()) + " cameras");
      sync_ = std::make_unique<FrameSetSync<sensor_msgs::ImageConstPtr>>(
          int(topics_.size()), cfg.policy, cfg.max_interval, std::size_t(cfg.queue_size), cfg.time_reset_threshold);
    } catch (const std::exception& e) {
      NODELET_FATAL("frame sync not started: %s", e.what());
      return;
    }
    cams_.resize(topics_.size());
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    auto connect = [this](const ros::SingleSubscriberPublisher&) { updateSubscription(); };
    pub_ = nh.advertise<CameraFrameSet>("frames", 5, connect, connect);
    diag_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, getName());
    diag_->setHardwareID("fisheye rig (" + std::to_string(topics_.size()) + " cameras)");
    diag_->add("frame sets", this, &FrameSyncNodelet::diagnose);
    diag_timer_ = nh.createWallTimer(ros::WallDuration(1.0), [this](const ros::WallTimerEvent&) {
      try {
        diag_->force_update();
      } catch (const std::exception& e) {
        health_.error(std::string("diagnostics: ") + e.what());
        NODELET_ERROR_THROTTLE(10.0, "diagnostics not published: %s", e.what());
      }
    });
    clock_timer_ = nh.createWallTimer(ros::WallDuration(0.2), [this](const ros::WallTimerEvent&) { checkClock(); });
    std::string list;
    for (const auto& t : topics_) list += " " + t;
    NODELET_INFO("frame sync: %zu cameras (%s policy, max interval %.4f s):%s", topics_.size(),
                 toString(cfg_.policy).c_str(), cfg_.max_interval, list.c_str());
  }

  void updateSubscription() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    try {
      subscribeIfWanted();
    } catch (const std::exception& e) {  // e.g. an image_transport plugin that is not installed
      health_.error(std::string("subscribing: ") + e.what());
      NODELET_ERROR("cannot subscribe the camera topics (~image_transport '%s'): %s", transport_.c_str(), e.what());
      subs_.clear();
    }
  }

  void subscribeIfWanted() {
    const bool wanted = pub_.getNumSubscribers() > 0;
    if (wanted && subs_.empty()) {
      for (size_t i = 0; i < topics_.size(); ++i) {
        subs_.push_back(it_->subscribe(topics_[i], 5,
                                       boost::bind(&FrameSyncNodelet::onImage, this, boost::placeholders::_1, int(i)),
                                       ros::VoidPtr(), image_transport::TransportHints(transport_)));
      }
      started_ = ros::Time::now();
    } else if (!wanted && !subs_.empty()) {
      subs_.clear();
    }
  }

  // Under sim time: a clock gone back behind the newest image resets the sync.
  void checkClock() {
    const std::int64_t now = simClockNs();
    if (!now) return;
    std::lock_guard<std::mutex> lock(mutex_);
    try {
      if (auto r = sync_->clockAt(now)) onTimeReset(*r);
    } catch (const std::exception& e) {
      health_.error(std::string("clock check: ") + e.what());
      NODELET_ERROR_THROTTLE(10.0, "clock check failed: %s", e.what());
    }
  }

  void onTimeReset(const FrameSetSync<sensor_msgs::ImageConstPtr>::TimeReset& r) {
    NODELET_WARN("frame sync: time went backwards from %s s to %s s: %s", formatStamp(r.from_ns).c_str(),
                 formatStamp(r.to_ns).c_str(), r.reason.c_str());
    health_.timeReset(formatStamp(r.from_ns) + " s -> " + formatStamp(r.to_ns) + " s: " + r.reason);
    seen_resets_ = sync_->stats().time_resets;
    // Arrival times are ROS time: after the clock went back they lie ahead.
    const ros::Time now = ros::Time::now();
    for (auto& c : cams_) {
      if (c.received) c.last_arrival = now;
    }
    started_ = now;
  }

  void onImage(const sensor_msgs::ImageConstPtr& msg, int cam) {
    std::lock_guard<std::mutex> lock(mutex_);
    try {
      addImage(msg, cam);
    } catch (const std::exception& e) {
      health_.error("image at " + formatStamp(std::int64_t(msg->header.stamp.toNSec())) + " from " + topics_[cam] +
                    ": " + e.what());
      NODELET_ERROR_THROTTLE(1.0, "%s (%s): image at %.3f skipped: %s", rig_.cameras[cam].name.c_str(),
                             topics_[cam].c_str(), msg->header.stamp.toSec(), e.what());
    } catch (...) {
      health_.error("image at " + formatStamp(std::int64_t(msg->header.stamp.toNSec())) + " from " + topics_[cam] +
                    ": unknown exception");
      NODELET_ERROR_THROTTLE(1.0, "%s (%s): image at %.3f skipped: unknown exception", rig_.cameras[cam].name.c_str(),
                             topics_[cam].c_str(), msg->header.stamp.toSec());
    }
  }

  void addImage(const sensor_msgs::ImageConstPtr& msg, int cam) {
    auto& c = cams_[cam];
    c.received++;
    c.last_arrival = ros::Time::now();
    const auto& model = rig_.cameras[cam].model;
    try {
      checkCameraImage(*msg, topics_[cam]);
    } catch (const ImageConversionError& e) {
      ++c.bad;
      NODELET_ERROR_THROTTLE(2.0, "%s: %s; dropped", rig_.cameras[cam].name.c_str(), e.what());
      return;
    }
    if (int(msg->width) != model.width() || int(msg->height) != model.height()) {
      ++c.bad;
      NODELET_ERROR_THROTTLE(2.0, "%s (%s): image %ux%u %s dropped: the calibration says %dx%d",
                             rig_.cameras[cam].name.c_str(), topics_[cam].c_str(), msg->width, msg->height,
                             msg->encoding.c_str(), model.width(), model.height());
      return;
    }
    auto sets = sync_->add(cam, std::int64_t(msg->header.stamp.toNSec()), msg);
    if (sync_->stats().time_resets != seen_resets_ && sync_->lastTimeReset()) onTimeReset(*sync_->lastTimeReset());
    for (auto& images : sets) {
      CameraFrameSetPtr out(new CameraFrameSet);
      out->header = images[0]->header;
      if (out->header.frame_id.empty()) out->header.frame_id = rig_.cameras[0].frame_id;
      for (size_t i = 0; i < images.size(); ++i) {
        out->camera_names.push_back(rig_.cameras[i].name);
        out->images.push_back(*images[i]);
      }
      latency_sum_ += (ros::Time::now() - out->header.stamp).toSec();
      pub_.publish(out);
    }
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    std::lock_guard<std::mutex> lock(mutex_);
    try {
      diagnoseLocked(stat);
    } catch (const std::exception& e) {
      stat.summary(diagnostic_msgs::DiagnosticStatus::ERROR, std::string("diagnostics failed: ") + e.what());
    }
  }

  void diagnoseLocked(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    const ros::WallTime now = ros::WallTime::now();
    const ros::Time ros_now = ros::Time::now();  // sim time when a bag plays the clock
    if (started_.isZero()) started_ = ros_now;    // no clock yet when the subscription started
    const double dt = std::max(1e-3, (now - last_diag_).toSec());
    const auto& s = sync_->stats();
    const double rate = (s.complete - last_complete_) / dt;
    stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "synchronizing");
    std::string silent;
    for (size_t i = 0; i < cams_.size(); ++i) {
      auto& c = cams_[i];
      stat.addf(rig_.cameras[i].name + " rate (Hz)", "%.2f", (c.received - c.last_received) / dt);
      c.last_received = c.received;
      const ros::Time since = c.received ? c.last_arrival : started_;
      if (!subs_.empty() && !since.isZero() && (ros_now - since).toSec() > silent_s_) silent += " " + rig_.cameras[i].name + "(" + topics_[i] + ")";
      if (c.bad) stat.add(rig_.cameras[i].name + " bad images", c.bad);
    }
    stat.addf("frame sets out (Hz)", "%.2f", rate);
    stat.add("frame sets out", s.complete);
    stat.add("incomplete sets dropped", s.dropped_incomplete);
    stat.add("out-of-order images dropped", s.dropped_out_of_order);
    stat.add("stale images dropped (old timeline)", s.dropped_stale);
    stat.addf("mean latency (s)", "%.3f", s.complete ? latency_sum_ / s.complete : 0.0);
    if (!silent.empty()) {
      stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::ERROR, "no images from" + silent);
      NODELET_WARN_THROTTLE(10.0, "no images for more than %.1f s from:%s", silent_s_, silent.c_str());
    } else if (s.dropped_incomplete > last_dropped_) {
      stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, "incomplete frame sets dropped");
      NODELET_WARN_THROTTLE(10.0, "%lu incomplete frame sets dropped so far", (unsigned long)s.dropped_incomplete);
    }
    health_.report(stat);
    last_dropped_ = s.dropped_incomplete;
    last_complete_ = s.complete;
    last_diag_ = now;
  }

  struct CamStats {
    std::uint64_t received = 0, last_received = 0, bad = 0;
    ros::Time last_arrival;
  };
  FrameSyncConfig cfg_;
  Rig rig_;
  std::vector<std::string> topics_;
  std::string transport_;
  double silent_s_ = 2.0;
  std::unique_ptr<FrameSetSync<sensor_msgs::ImageConstPtr>> sync_;
  std::vector<CamStats> cams_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  std::vector<image_transport::Subscriber> subs_;
  ros::Publisher pub_;
  std::unique_ptr<diagnostic_updater::Updater> diag_;
  ros::WallTimer diag_timer_, clock_timer_;
  StageHealth health_;
  std::uint64_t seen_resets_ = 0;
  ros::Time started_;
  ros::WallTime last_diag_ = ros::WallTime::now();
  std::uint64_t last_complete_ = 0, last_dropped_ = 0;
  double latency_sum_ = 0;
  std::mutex mutex_, connect_mutex_;
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::FrameSyncNodelet, nodelet::Nodelet)
