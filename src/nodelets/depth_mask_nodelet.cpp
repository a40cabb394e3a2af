// Depth mask nodelet (fisheye_mapping/DepthMask): removes potentially moving
// objects from depth maps before fusion (paper Sec. III-B).
//
// Its topics (relative to the node's namespace), parameters and diagnostics:
// docs/nodelets.md#fisheye_mappingdetector-and-fisheye_mappingdepthmask; every
// parameter: docs/parameters.md; the vehicles' motion: docs/dynamic_objects.md.
// - Depth maps and detections pair by exact stamp; a depth map waits up to
//   ~wait_for_detections (wall time), then passes unmasked (a drop by reason).
// - Each detected vehicle is placed in ~world_frame by the depth in its box
//   and tracked (core VehicleMotionTracker): moving and undecided ones are
//   masked (every box with ~mask_parked); the regions of parked vehicles that
//   drove off go out on depth_masked/vehicles for the TSDF to carve. The
//   depth an undecided vehicle masked is held (~hold_time, core
//   VehicleDepthHold) and goes out on depth_masked/held, stamped with its
//   frame set, once the vehicle is decided parked, for the TSDF to fuse.
// - depth_masked/camera_info is the latest depth/camera_info with the masked
//   depth's header (core InfoRelay: latched, and republished when it comes
//   after a depth map); masking never waits for it.
// - Time going backwards on either stream (or the sim clock behind the newest
//   stamp) clears the pairing state: depth maps of the old timeline are
//   dropped, not published (a bag played twice would else pass unmasked).
#include <memory>
#include <mutex>
#include <optional>

#include <boost/thread/recursive_mutex.hpp>
#include <dynamic_reconfigure/server.h>
#include <image_transport/camera_common.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include "fisheye_mapping/DepthMaskReconfigureConfig.h"
#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/TrackedVehicleArray.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/detection/depth_mask.h"
#include "fisheye_mapping/core/detection/held_depth.h"
#include "fisheye_mapping/core/detection/mask_decisions.h"
#include "fisheye_mapping/ros/camera_info.h"
#include "fisheye_mapping/ros/camera_models.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/node_options.h"
#include "fisheye_mapping/ros/nodelet_glue.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_messages.h"
#include "fisheye_mapping/ros/stage_monitor.h"

namespace fisheye_mapping {

class DepthMaskNodelet : public nodelet::Nodelet {
 private:
  using Pairer = StampPairer<sensor_msgs::ImageConstPtr, Detection2DArrayConstPtr>;
  using ReconfigureConfig = DepthMaskReconfigureConfig;
  enum Stream { kDepth = 0, kDetections = 1 };

  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    log_ = NodeletLogger(getName());
    // Every masking parameter is declared once, in the core (DepthMaskConfig);
    // the node's own in DepthMaskNodeOptions. A bad one stops the stage, as in
    // every stage.
    try {
      requireKnownParams(pnh, {DepthMaskConfig::params().names(), DepthMaskNodeOptions::params().names()});
      cfg_ = DepthMaskConfig::fromParams(RosParams(pnh));
      opts_ = DepthMaskNodeOptions::params().read(RosParams(pnh), DepthMaskNodeOptions());
      monitor_ = std::make_unique<StageMonitor>(nh, pnh, "depth_mask");
    } catch (const std::exception& e) {
      NODELET_FATAL("depth mask not started: %s", e.what());
      return;
    }
    monitor_->setInputExpected(false);
    pairer_ = std::make_unique<Pairer>(cfg_.wait_for_detections, std::size_t(cfg_.max_pending));
    tracker_ = std::make_unique<VehicleMotionTracker>(cfg_.motion);
    hold_ = std::make_unique<VehicleDepthHold>(cfg_.mask_parked ? 0.0 : cfg_.hold_time);
    tf_buffer_ = std::make_unique<tf2_ros::Buffer>(ros::Duration(30.0));
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
    vehicles_pub_ = nh.advertise<TrackedVehicleArray>("depth_masked/vehicles", 5);
    held_pub_ = nh.advertise<sensor_msgs::Image>("depth_masked/held", 10);
    // A time reset clears the pairing (keyed on stamps) and the tracks; the
    // depth maps still waiting belong to the old timeline and are dropped.
    time_ = std::make_unique<StageTimeline>(
        *monitor_, log_, "depth mask", std::vector<std::string>{"depth", "detections"}, cfg_.time_reset_threshold,
        [this](const StreamTimeline::Event&, const std::string&) {
          tracker_->reset();
          hold_->reset();
          const std::size_t dropped = pairer_->pendingDepth();
          for (std::size_t i = 0; i < dropped; ++i) monitor_->dropped("time reset (waiting depth maps)");
          pairer_ = std::make_unique<Pairer>(cfg_.wait_for_detections, std::size_t(cfg_.max_pending));
          return "pairing reset, " + std::to_string(dropped) + " waiting depth map(s) dropped";
        });
    monitor_->setExtraReport([this](diagnostic_updater::DiagnosticStatusWrapper& stat) { report(stat); });
    // image_transport's convention: the CameraInfo next to the (resolved, remapped) image topic.
    info_in_topic_ = image_transport::getCameraInfoTopic(nh.resolveName("depth/image"));
    relay_ = std::make_unique<InfoRelay<std_msgs::Header>>(info_in_topic_);
    // Latched: a subscriber that connects after a depth map went out (the
    // TSDF stage holds that depth until its CameraInfo comes) still gets it.
    info_pub_ = nh.advertise<sensor_msgs::CameraInfo>(
        image_transport::getCameraInfoTopic(nh.resolveName("depth_masked/image")), 5, true);
    timer_ = nh.createWallTimer(ros::WallDuration(timerPeriod(cfg_.wait_for_detections)),
                                [this](const ros::WallTimerEvent&) { onTimer(); });
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<ReconfigureConfig>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](ReconfigureConfig& c, uint32_t) { onReconfigure(c); });
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    input_ = std::make_unique<LazySubscription>(
        *monitor_, log_, "depth / detections (~image_transport '" + opts_.image_transport + "')",
        [this] {
          return masked_pub_.getNumSubscribers() > 0 || mask_pub_.getNumSubscribers() > 0 ||
                 colour_pub_.getNumSubscribers() > 0;
        },
        [this] {
          ros::NodeHandle& nh = getNodeHandle();
          depth_sub_ = it_->subscribe("depth/image", 5, &DepthMaskNodelet::onDepth, this,
                                      image_transport::TransportHints(opts_.image_transport));
          det_sub_ = nh.subscribe("detections", 10, &DepthMaskNodelet::onDetections, this);
          info_sub_ = nh.subscribe(info_in_topic_, 2, &DepthMaskNodelet::onCameraInfo, this);
        },
        [this] {
          depth_sub_.shutdown();
          det_sub_.shutdown();
          info_sub_.shutdown();
        });
    const auto connect = input_->imageCallback();
    masked_pub_ = it_->advertise("depth_masked/image", 5, connect, connect);
    mask_pub_ = it_->advertise("depth_masked/mask", 5, connect, connect);
    colour_pub_ = it_->advertise("depth_masked/colour", 2, connect, connect);
    // A subscriber that connected while the publishers above were being
    // assigned may have run the connect callback too early (it saw none):
    // look once more now that all of them exist.
    input_->update();
  }

  // Polls the pairing often enough that a depth map leaves close to its wait.
  static double timerPeriod(double wait) { return std::max(0.005, std::min(0.05, wait / 4)); }
  static double now() { return ros::WallTime::now().toSec(); }

  // The run-time parameters of DepthMaskConfig::params(), each against its
  // declaration (cfg/DepthMaskReconfigure.cfg is checked against them by
  // test_param_declarations). A refused value leaves the running ones, which go
  // back to the caller. Waiting depth maps keep waiting, under the new wait.
  void onReconfigure(ReconfigureConfig& c) {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto next = checkedReconfigure(c, DepthMaskConfig::params(), cfg_, *monitor_, log_, "depth mask parameters");
    if (!next) return;
    pairer_->setWait(next->wait_for_detections);
    pairer_->setMaxPending(std::size_t(next->max_pending));
    if (next->time_reset_threshold != cfg_.time_reset_threshold) time_->setThreshold(next->time_reset_threshold);
    if (next->wait_for_detections != cfg_.wait_for_detections)
      timer_.setPeriod(ros::WallDuration(timerPeriod(next->wait_for_detections)));
    cfg_ = *next;
    NODELET_INFO("depth mask: margin %.1f px, waits %.3f s for detections, holds %d, time reset after %.3g s",
                 cfg_.margin_px, cfg_.wait_for_detections, cfg_.max_pending, cfg_.time_reset_threshold);
  }

  void onDepth(const sensor_msgs::ImageConstPtr& msg) {
    monitor_->input();
    try {
      checkDepthImage(*msg, getNodeHandle().resolveName("depth/image"));
    } catch (const ImageConversionError& e) {  // the sender's fault: a drop, not a stage error
      monitor_->dropped("bad depth image");
      NODELET_ERROR_THROTTLE(1.0, "depth at %.3f skipped: %s", msg->header.stamp.toSec(), e.what());
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    guarded(*monitor_, log_, "depth", msg->header.stamp, [&] {
      if (time_->observe(kDepth, msg->header.stamp)) publish(pairer_->addDepth(msg->header.stamp.toNSec(), msg, now()));
    });
  }

  void onDetections(const Detection2DArrayConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    guarded(*monitor_, log_, "detections", msg->header.stamp, [&] {
      if (!time_->observe(kDetections, msg->header.stamp)) return;
      const auto late = pairer_->late(), overflow = pairer_->detectionsDropped();
      publish(pairer_->addDetections(msg->header.stamp.toNSec(), msg, now()));
      if (pairer_->detectionsDropped() != overflow) monitor_->dropped("queue full (detection sets)");
      if (pairer_->late() != late) {
        monitor_->dropped("late detections");
        NODELET_WARN_THROTTLE(5.0, "detections at %.3f came after their depth map had passed through",
                              msg->header.stamp.toSec());
      }
    });
  }

  void onCameraInfo(const sensor_msgs::CameraInfoConstPtr& msg) {
    std::lock_guard<std::mutex> lock(info_mutex_);
    info_ = msg;
    // A masked depth went out before any CameraInfo had come (the depth
    // stage publishes both; they race): its CameraInfo now, so that a
    // consumer waiting for it (the TSDF stage) need not wait for the next.
    if (const auto waiting = relay_->info(int(msg->width), int(msg->height)))
      publishCameraInfoLocked(waiting->header, waiting->width, waiting->height);
  }

  void onTimer() {
    const std::int64_t clock = simClockNs();
    std::lock_guard<std::mutex> lock(mutex_);
    guarded(*monitor_, log_, "timer", ros::Time(), [&] {
      if (clock) time_->clock(clock, "clock");
      publish(pairer_->poll(now()));
    });
  }

  // The stage's own values after StageMonitor's standard ones.
  void report(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      // Kept under its old name: tools and the time-reset rostest read it.
      stat.add("passed unmasked (no detections in time)", unmasked_);
      stat.addf("margin (px)", "%g", cfg_.margin_px);
      stat.addf("wait for detections (s)", "%g", cfg_.wait_for_detections);
      stat.add("max pending", cfg_.max_pending);
      stat.add("vehicle motion", motion_state_);
      stat.add("vehicles moving / parked / undecided", counts_.text());
      stat.add("parked vehicles masked", cfg_.mask_parked ? "yes (mask_parked)" : "no");
      stat.add("held depth (pixels now / frame sets released)",
               std::to_string(hold_->heldPixels()) + " / " + std::to_string(hold_->releasedFrames()));
    }
    std::lock_guard<std::mutex> lock(info_mutex_);
    stat.add("camera_info", relay_->state("depth_masked/camera_info"));
  }

  // The latest CameraInfo with the masked depth's header, when it fits the
  // depth map; never waited for (info_mutex_ held).
  void publishCameraInfoLocked(const std_msgs::Header& header, int width, int height) {
    switch (relay_->output(header, width, height)) {
      case InfoRelay<std_msgs::Header>::Action::kWait:
        if (relay_->firstWait())
          NODELET_INFO("no CameraInfo on %s (yet): depth_masked/camera_info is published once one arrives",
                       info_in_topic_.c_str());
        return;
      case InfoRelay<std_msgs::Header>::Action::kMismatch:
        NODELET_WARN_THROTTLE(10.0, "%s", relay_->problem().c_str());
        return;
      case InfoRelay<std_msgs::Header>::Action::kSend: {
        sensor_msgs::CameraInfo out = *info_;
        out.header = header;
        info_pub_.publish(out);
      }
    }
  }

  // Called with mutex_ held.
  void publish(const std::vector<Pairer::Pair>& pairs) {
    for (const auto& p : pairs) guarded(*monitor_, log_, "depth", p.depth->header.stamp, [&] { publishPair(p); });
  }

  void publishPair(const Pairer::Pair& p) {
    const double t0 = StageStats::now();
    const std_msgs::Header& header = p.depth->header;
    cv::Mat depth = toDepth(*p.depth);
    std::vector<Detection> boxes;
    int w = depth.cols, h = depth.rows;
    if (p.dets) {
      StampedDetections d = fromDetectionArrayMsg(**p.dets);
      if (d.image_width > 0 && d.image_height > 0) w = d.image_width, h = d.image_height;
      boxes = std::move(d.detections);
    } else {
      ++unmasked_;
      monitor_->dropped(p.queue_full ? "queue full (passed unmasked)" : "no detections in time (passed unmasked)");
      NODELET_WARN_THROTTLE(5.0, "no detections for depth at %.3f %s; passed through unmasked (%lu so far)",
                            header.stamp.toSec(), p.queue_full ? "(queue full)" : "within the wait",
                            (unsigned long)unmasked_);
    }
    // Which vehicles move, from the depth before masking.
    const std::vector<VehicleMotionTracker::Decision> decisions = decide(header, depth, boxes, w, h);
    // The depth undecided vehicles mask is held; that of the vehicles decided
    // parked now goes out on depth_masked/held, stamped with its frame set.
    std::vector<VehicleDepthHold::Frame> released;
    if (!cfg_.mask_parked) {
      released = hold_->update(std::int64_t(header.stamp.toNSec()), depth, boxes, decisions, float(cfg_.margin_px), w, h);
    }
    const cv::Mat mask = maskDepthBoxes(depth, boxesToMask(boxes, decisions, cfg_.mask_parked), float(cfg_.margin_px), w, h);
    masked_pub_.publish(toDepthMsg(header, depth));
    mask_pub_.publish(toImageMsg(header, mask));  // mono8
    if (p.dets) {
      vehicles_pub_.publish(toTrackedVehicleArrayMsg(header, opts_.world_frame, w, h, **p.dets, decisions,
                                                     cfg_.mask_parked, tracker_->ghostRegions()));
    }
    for (const auto& f : released) {
      std_msgs::Header held = header;
      held.stamp.fromNSec(std::uint64_t(f.stamp_ns));
      held_pub_.publish(toDepthMsg(held, f.depth));
    }
    if (colour_pub_.getNumSubscribers() > 0) {
      cv::Mat colour = colorizeDepth(depth, cfg_.colour_near, cfg_.colour_far);
      drawVehicleDecisions(&colour, boxes, decisions, w, h);
      colour_pub_.publish(toImageMsg(header, colour));
    }
    {
      std::lock_guard<std::mutex> lock(info_mutex_);
      publishCameraInfoLocked(header, int(p.depth->width), int(p.depth->height));
    }
    monitor_->processed(StageStats::now() - t0);
    monitor_->output();
  }

  // Each box's decision (called with mutex_ held): all undecided without a
  // camera (depth/camera_info of the depth's size) or the world pose, named
  // in motion_state_.
  std::vector<VehicleMotionTracker::Decision> decide(const std_msgs::Header& header, const cv::Mat& depth,
                                                     const std::vector<Detection>& boxes, int w, int h) {
    if (boxes.empty()) return {};
    std::string why;
    std::optional<CameraModel> camera;
    {
      std::lock_guard<std::mutex> lock(info_mutex_);
      if (const auto c = cameras_.fitting(info_, depth.cols, depth.rows, info_in_topic_, &why)) camera = *c;
    }
    if (!camera) why += ": every vehicle masked";
    const std::string& world = opts_.world_frame;
    std::optional<Eigen::Isometry3d> T_W_C;
    if (camera) {
      try {
        T_W_C = toIsometry(tf_buffer_->lookupTransform(world, header.frame_id, header.stamp));
      } catch (const std::exception& e) {
        monitor_->tfFailure(world + " -> " + header.frame_id);
        why = "no tf " + world + " -> " + header.frame_id + " at " + formatStamp(std::int64_t(header.stamp.toNSec())) +
              " s: every vehicle masked (" + e.what() + ")";
      }
    }
    const auto out = decideVehicles(*tracker_, boxes, w, h, depth, camera ? &*camera : nullptr, T_W_C,
                                    header.stamp.toSec(), world, why, &motion_state_);
    counts_.add(out);
    return out;
  }

  DepthMaskConfig cfg_;  // the running parameters
  DepthMaskNodeOptions opts_;
  NodeletLogger log_;
  std::unique_ptr<VehicleMotionTracker> tracker_;
  std::unique_ptr<VehicleDepthHold> hold_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  ros::Publisher vehicles_pub_, held_pub_;
  CameraModelsByFrame cameras_;  // info_mutex_
  std::string motion_state_ = "no vehicle yet";
  MotionCounts counts_;
  std::string info_in_topic_;
  std::unique_ptr<Pairer> pairer_;
  std::uint64_t unmasked_ = 0;
  std::mutex mutex_, info_mutex_;
  sensor_msgs::CameraInfoConstPtr info_;                    // info_mutex_
  std::unique_ptr<InfoRelay<std_msgs::Header>> relay_;      // info_mutex_
  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::Subscriber depth_sub_;
  ros::Subscriber det_sub_, info_sub_;
  image_transport::Publisher masked_pub_, mask_pub_, colour_pub_;
  ros::Publisher info_pub_;
  ros::WallTimer timer_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<ReconfigureConfig>> reconfigure_;
  std::unique_ptr<StageMonitor> monitor_;  // before the glue that refers to it
  std::unique_ptr<StageTimeline> time_;    // mutex_
  std::unique_ptr<LazySubscription> input_;
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::DepthMaskNodelet, nodelet::Nodelet)
