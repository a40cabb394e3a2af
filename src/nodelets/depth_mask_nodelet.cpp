// Depth mask nodelet: removes potentially moving objects from depth maps
// before fusion (paper Sec. III-B).
//
// Topics are relative to the node's namespace (vehicle.launch: /fisheye_mapping).
// Subscribes  depth/image (sensor_msgs/Image 32FC1, range along the ray, NaN
//             invalid; through image_transport, ~image_transport selects the transport)
//             depth/camera_info (optional: the depth's CameraInfo, next to depth/image)
//             detections (fisheye_mapping/Detection2DArray of the same camera)
//             while someone listens to an image output (lazy).
// Publishes   through image_transport, all with the depth map's header:
//             depth_masked/image  (32FC1: NaN inside the boxes of the moving
//                          and undecided vehicles, grown by ~margin_px; of
//                          every box with ~mask_parked)
//             depth_masked/mask   (mono8: 255 where a box removed depth)
//             depth_masked/colour (bgr8: colour-coded masked depth, black
//                          invalid, each box drawn with its decision: red
//                          moving, green parked, yellow undecided; only
//                          while subscribed; ~colour_range [near, far])
//             depth_masked/vehicles (fisheye_mapping/TrackedVehicleArray:
//                          each detection's decision, masked or not, track,
//                          speed, position in ~world_frame, and the regions
//                          of parked vehicles that drove off, which the TSDF
//                          fusion carves free; for every depth map that came
//                          with detections)
//             depth_masked/camera_info: the latest depth/camera_info with the
//                          masked depth's header (none until one has arrived;
//                          masking never waits for it; said once in the log
//                          and in the diagnostics).
// Vehicles   each detected vehicle is placed in ~world_frame (default map)
//             by the depth in its box, with depth/camera_info's camera and tf
//             from ~world_frame to the depth's frame at its stamp, and
//             tracked: moving, parked or undecided (core VehicleMotionTracker;
//             ~moving_speed, ~decide_after, ...). Without a camera_info or the
//             transform every vehicle is undecided, so masked (diagnostics
//             "vehicle motion" names what is missing; a tf failure is counted).
// Pairing     by exact stamp. A depth map waits up to ~wait_for_detections
//             seconds (wall time) for its detections; then it passes through
//             unmasked and is counted as a drop by reason (warning).
//             A frame whose detections are empty passes unchanged.
// Parameters  ~margin_px (default 10), ~wait_for_detections (default 0.5 s),
//             ~max_pending (default 30 depth maps / detection sets),
//             ~time_reset_threshold (s, default 1; 0: never), ~colour_range.
//             All but colour_range also through dynamic_reconfigure
//             (cfg/DepthMaskReconfigure.cfg), read by the same DepthMaskConfig::fromParams.
// Time going backwards (depth or detection stamps back by more than the
// threshold on their own stream, or the sim clock behind the newest stamp):
// the pairing state, keyed on stamps, is cleared (depth maps still waiting are
// dropped, not published: they belong to the old timeline; so are depth maps
// and detections of the old timeline still in flight), with a warning naming
// both stamps. Without it, a bag played twice would find its detections
// "late" (their stamps were released in the first play) and pass every depth
// map unmasked.
// /diagnostics (StageMonitor, task "depth_mask"): depth rates in / out, masking
// time, drops by reason ("no detections in time (passed unmasked)", "queue
// full (passed unmasked)", "queue full (detection sets)", "late detections",
// "time reset (waiting depth maps)", "stale (old timeline)", "bad depth
// image"), time resets, callback errors, "passed unmasked (no detections in
// time)" (total), "camera_info" and the parameters in use.
#include <atomic>
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

#include <opencv2/imgproc.hpp>

#include "fisheye_mapping/DepthMaskReconfigureConfig.h"

#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/TrackedVehicleArray.h"
#include "fisheye_mapping/ros/camera_info.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/detection/depth_mask.h"
#include "fisheye_mapping/core/common/stream_timeline.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/node_options.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_monitor.h"

namespace fisheye_mapping {

class DepthMaskNodelet : public nodelet::Nodelet {
 private:
  using Pairer = StampPairer<sensor_msgs::ImageConstPtr, Detection2DArrayConstPtr>;
  using ReconfigureConfig = DepthMaskReconfigureConfig;

  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    // Every masking parameter is declared once, in the core (DepthMaskConfig);
    // the node's own in DepthMaskNodeOptions. A bad one stops the stage, as in
    // every stage.
    try {
      requireKnownParams(pnh, {DepthMaskConfig::params().names(), DepthMaskNodeOptions::params().names()});
      cfg_ = DepthMaskConfig::fromParams(RosParams(pnh));
      const DepthMaskNodeOptions options = DepthMaskNodeOptions::params().read(RosParams(pnh), DepthMaskNodeOptions());
      transport_ = options.image_transport;
      world_frame_ = options.world_frame;
      monitor_ = std::make_unique<StageMonitor>(nh, pnh, "depth_mask");
    } catch (const std::exception& e) {
      NODELET_FATAL("depth mask not started: %s", e.what());
      return;
    }
    monitor_->setInputExpected(false);
    pairer_ = std::make_unique<Pairer>(cfg_.wait_for_detections, std::size_t(cfg_.max_pending));
    tracker_ = std::make_unique<VehicleMotionTracker>(cfg_.motion);
    tf_buffer_ = std::make_unique<tf2_ros::Buffer>(ros::Duration(30.0));
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
    vehicles_pub_ = nh.advertise<TrackedVehicleArray>("depth_masked/vehicles", 5);
    timeline_ = std::make_unique<StreamTimeline>(2, cfg_.time_reset_threshold);
    monitor_->setExtraReport([this](diagnostic_updater::DiagnosticStatusWrapper& stat) { report(stat); });
    // image_transport's convention: the CameraInfo next to the (resolved, remapped) image topic.
    info_in_topic_ = image_transport::getCameraInfoTopic(nh.resolveName("depth/image"));
    // Latched: a subscriber that connects after a depth map went out (the
    // TSDF stage holds that depth until its CameraInfo comes) still gets it.
    info_pub_ = nh.advertise<sensor_msgs::CameraInfo>(
        image_transport::getCameraInfoTopic(nh.resolveName("depth_masked/image")), 5, true);
    timer_ = nh.createWallTimer(ros::WallDuration(timerPeriod(cfg_.wait_for_detections)),
                                [this](const ros::WallTimerEvent&) { onTimer(); });
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<ReconfigureConfig>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](ReconfigureConfig& c, uint32_t) { onReconfigure(c); });
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    auto connect = [this](const image_transport::SingleSubscriberPublisher&) { updateSubscription(); };
    masked_pub_ = it_->advertise("depth_masked/image", 5, connect, connect);
    mask_pub_ = it_->advertise("depth_masked/mask", 5, connect, connect);
    colour_pub_ = it_->advertise("depth_masked/colour", 2, connect, connect);
    // A subscriber that connected while the publishers above were being
    // assigned may have run the connect callback too early (it saw none):
    // look once more now that all of them exist.
    updateSubscription();
  }

  // Polls the pairing often enough that a depth map leaves close to its wait.
  static double timerPeriod(double wait) { return std::max(0.005, std::min(0.05, wait / 4)); }

  // The run-time parameters of DepthMaskConfig::params(), each against its
  // declaration (cfg/DepthMaskReconfigure.cfg is checked against them by
  // test_param_declarations). A refused value leaves the running ones, which go
  // back to the caller.
  void onReconfigure(ReconfigureConfig& c) {
    dynamic_reconfigure::Config values;
    c.__toMessage__(values);
    std::lock_guard<std::mutex> lock(mutex_);
    std::string error;
    if (const std::optional<DepthMaskConfig> next = reconfigured(DepthMaskConfig::params(), cfg_, values, error)) {
      apply(*next);
      return;
    }
    monitor_->error("parameters refused: " + error);
    NODELET_ERROR("depth mask parameters refused, keeping the running ones: %s", error.c_str());
    keepRunningValues(c, std::make_pair(std::cref(DepthMaskConfig::params()), cfg_));
  }

  // Called with mutex_ held (at start-up too: the server's first call). Waiting
  // depth maps keep waiting, under the new wait.
  void apply(const DepthMaskConfig& next) {
    pairer_->setWait(next.wait_for_detections);
    pairer_->setMaxPending(std::size_t(next.max_pending));
    if (next.time_reset_threshold != cfg_.time_reset_threshold)
      timeline_ = std::make_unique<StreamTimeline>(2, next.time_reset_threshold);
    if (next.wait_for_detections != cfg_.wait_for_detections)
      timer_.setPeriod(ros::WallDuration(timerPeriod(next.wait_for_detections)));
    cfg_ = next;
    NODELET_INFO("depth mask: margin %.1f px, waits %.3f s for detections, holds %d, time reset after %.3g s",
                 cfg_.margin_px, cfg_.wait_for_detections, cfg_.max_pending, cfg_.time_reset_threshold);
  }

  void updateSubscription() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    try {
      subscribeIfWanted();
    } catch (const std::exception& e) {
      monitor_->error(std::string("subscribing: ") + e.what());
      NODELET_ERROR("cannot subscribe depth / detections (~image_transport '%s'): %s", transport_.c_str(), e.what());
    }
  }

  void subscribeIfWanted() {
    ros::NodeHandle& nh = getNodeHandle();
    const bool wanted = masked_pub_.getNumSubscribers() > 0 || mask_pub_.getNumSubscribers() > 0 ||
                        colour_pub_.getNumSubscribers() > 0;
    if (wanted && !depth_sub_) {
      depth_sub_ = it_->subscribe("depth/image", 5, &DepthMaskNodelet::onDepth, this,
                                  image_transport::TransportHints(transport_));
      det_sub_ = nh.subscribe("detections", 10, &DepthMaskNodelet::onDetections, this);
      info_sub_ = nh.subscribe(info_in_topic_, 2, &DepthMaskNodelet::onCameraInfo, this);
    } else if (!wanted && depth_sub_) {
      depth_sub_.shutdown();
      det_sub_.shutdown();
      info_sub_.shutdown();
    }
    monitor_->setInputExpected(wanted);
  }

  static double now() { return ros::WallTime::now().toSec(); }

  enum Stream { kDepth = 0, kDetections = 1 };

  // The stamp on its stream's timeline; false: a straggler of an old timeline (dropped).
  bool onTimeline(Stream stream, const ros::Time& stamp) {
    const auto ev = timeline_->observe(stream, std::int64_t(stamp.toNSec()));
    if (ev.kind == StreamTimeline::Kind::kStale) {
      monitor_->dropped("stale (old timeline)");
      return false;
    }
    if (ev.kind == StreamTimeline::Kind::kReset) resetTime(ev, stream == kDepth ? "depth" : "detections");
    return true;
  }

  // Called with mutex_ held.
  void resetTime(const StreamTimeline::Event& ev, const char* what) {
    tracker_->reset();
    const std::size_t dropped = pairer_->pendingDepth();
    for (std::size_t i = 0; i < dropped; ++i) monitor_->dropped("time reset (waiting depth maps)");
    pairer_ = std::make_unique<Pairer>(cfg_.wait_for_detections, std::size_t(cfg_.max_pending));
    NODELET_WARN("depth mask: time went backwards (%s) from %s s to %s s (%s); pairing reset, %zu waiting depth "
                 "map(s) dropped", what, formatStamp(ev.from_ns).c_str(), formatStamp(ev.to_ns).c_str(),
                 ev.reason.c_str(), dropped);
    monitor_->timeReset(std::string(what) + " " + formatStamp(ev.from_ns) + " s -> " + formatStamp(ev.to_ns) +
                        " s: " + ev.reason);
  }

  template <class F>
  void guarded(const char* what, const ros::Time& stamp, F&& f) {
    try {
      f();
    } catch (const std::exception& e) {
      monitor_->error(std::string(what) + " at " + formatStamp(std::int64_t(stamp.toNSec())) + ": " + e.what());
      NODELET_ERROR_THROTTLE(1.0, "%s at %.3f skipped: %s", what, stamp.toSec(), e.what());
    } catch (...) {
      monitor_->error(std::string(what) + " at " + formatStamp(std::int64_t(stamp.toNSec())) + ": unknown exception");
      NODELET_ERROR_THROTTLE(1.0, "%s at %.3f skipped: unknown exception", what, stamp.toSec());
    }
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
    guarded("depth", msg->header.stamp, [&] {
      if (!onTimeline(kDepth, msg->header.stamp)) return;
      publish(pairer_->addDepth(msg->header.stamp.toNSec(), msg, now()));
    });
  }

  void onDetections(const Detection2DArrayConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    guarded("detections", msg->header.stamp, [&] {
      if (!onTimeline(kDetections, msg->header.stamp)) return;
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
    if (unmatched_depth_) {
      sensor_msgs::Image depth = *unmatched_depth_;
      unmatched_depth_.reset();
      publishCameraInfoLocked(depth);
    }
  }

  void onTimer() {
    const std::int64_t clock = simClockNs();
    std::lock_guard<std::mutex> lock(mutex_);
    guarded("timer", ros::Time(), [&] {
      if (clock) {
        if (auto ev = timeline_->clock(clock)) resetTime(*ev, "clock");
      }
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
      stat.add("vehicles moving / parked / undecided",
               std::to_string(n_moving_) + " / " + std::to_string(n_parked_) + " / " + std::to_string(n_undecided_));
      stat.add("parked vehicles masked", cfg_.mask_parked ? "yes (mask_parked)" : "no");
    }
    stat.add("camera_info", cameraInfoState());
  }

  std::string cameraInfoState() {
    std::lock_guard<std::mutex> lock(info_mutex_);
    if (!info_) return "none received on " + info_in_topic_ + ": depth_masked/camera_info not published";
    if (!info_problem_.empty()) return info_problem_;
    return "republished from " + info_in_topic_;
  }

  // The latest CameraInfo with the masked depth's header, when it fits the
  // depth map; never waited for.
  void publishCameraInfo(const sensor_msgs::Image& depth) {
    std::lock_guard<std::mutex> lock(info_mutex_);
    publishCameraInfoLocked(depth);
  }
  void publishCameraInfoLocked(const sensor_msgs::Image& depth) {
    if (!info_) {
      if (!told_no_info_)
        NODELET_INFO("no CameraInfo on %s (yet): depth_masked/camera_info is published once one arrives",
                     info_in_topic_.c_str());
      told_no_info_ = true;
      // Its header and size (not its pixels), for the CameraInfo when it comes.
      sensor_msgs::Image header_only;
      header_only.header = depth.header;
      header_only.width = depth.width;
      header_only.height = depth.height;
      unmatched_depth_ = header_only;
      return;
    }
    if (info_->width != depth.width || info_->height != depth.height) {
      info_problem_ = "not republished: " + info_in_topic_ + " is " + std::to_string(info_->width) + "x" +
                      std::to_string(info_->height) + ", the depth " + std::to_string(depth.width) + "x" +
                      std::to_string(depth.height);
      NODELET_WARN_THROTTLE(10.0, "%s", info_problem_.c_str());
      return;
    }
    info_problem_.clear();
    sensor_msgs::CameraInfo out = *info_;
    out.header = depth.header;
    info_pub_.publish(out);
  }

  // Called with mutex_ held.
  void publish(const std::vector<Pairer::Pair>& pairs) {
    for (const auto& p : pairs) guarded("depth", p.depth->header.stamp, [&] { publishPair(p); });
  }

  void publishPair(const Pairer::Pair& p) {
    const double t0 = StageStats::now();
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
                            p.depth->header.stamp.toSec(), p.queue_full ? "(queue full)" : "within the wait",
                            (unsigned long)unmasked_);
    }
    // Which vehicles move, from the depth before masking.
    const std::vector<VehicleMotionTracker::Decision> decisions = decide(p.depth->header, depth, boxes, w, h);
    std::vector<Detection> masked;
    for (size_t i = 0; i < boxes.size(); ++i) {
      if (cfg_.mask_parked || decisions[i].motion != VehicleMotion::Parked) masked.push_back(boxes[i]);
    }
    const cv::Mat mask = maskDepthBoxes(depth, masked, float(cfg_.margin_px), w, h);
    masked_pub_.publish(toDepthMsg(p.depth->header, depth));
    mask_pub_.publish(toImageMsg(p.depth->header, mask));  // mono8
    if (p.dets) publishVehicles(p.depth->header, **p.dets, decisions, w, h);
    if (colour_pub_.getNumSubscribers() > 0) {
      cv::Mat colour = colorizeDepth(depth, cfg_.colour_near, cfg_.colour_far);
      drawDecisions(&colour, boxes, decisions, w, h);
      colour_pub_.publish(toImageMsg(p.depth->header, colour));
    }
    publishCameraInfo(*p.depth);
    monitor_->processed(StageStats::now() - t0);
    monitor_->output();
  }

  // Each box's decision (called with mutex_ held): all undecided without a
  // camera (depth/camera_info of the depth's size) or the world pose, named
  // in motion_state_.
  std::vector<VehicleMotionTracker::Decision> decide(const std_msgs::Header& header, const cv::Mat& depth,
                                                     const std::vector<Detection>& boxes, int w, int h) {
    std::vector<VehicleMotionTracker::Decision> none(boxes.size());
    if (boxes.empty()) return none;
    std::optional<CameraModel> camera;
    {
      std::lock_guard<std::mutex> lock(info_mutex_);
      if (!info_) {
        motion_state_ = "no camera_info on " + info_in_topic_ + ": every vehicle masked";
      } else if (int(info_->width) != depth.cols || int(info_->height) != depth.rows) {
        motion_state_ = "camera_info " + std::to_string(info_->width) + "x" + std::to_string(info_->height) +
                        " does not fit the depth: every vehicle masked";
      } else {
        if (info_ != camera_info_used_) {
          try {
            camera_ = fromCameraInfo(*info_);
          } catch (const std::exception& e) {
            camera_.reset();
            motion_state_ = std::string("camera_info refused: ") + e.what() + ": every vehicle masked";
          }
          camera_info_used_ = info_;
        }
        camera = camera_;
      }
    }
    std::optional<Eigen::Isometry3d> T_W_C;
    if (camera) {
      try {
        T_W_C = toIsometry(tf_buffer_->lookupTransform(world_frame_, header.frame_id, header.stamp));
      } catch (const std::exception& e) {
        monitor_->tfFailure(world_frame_ + " -> " + header.frame_id);
        motion_state_ = "no tf " + world_frame_ + " -> " + header.frame_id + " at " +
                        formatStamp(std::int64_t(header.stamp.toNSec())) + " s: every vehicle masked (" + e.what() +
                        ")";
      }
    }
    std::vector<VehicleMotionTracker::Decision> out = none;
    if (camera) {
      try {
        out = tracker_->update(boxes, w, h, depth, *camera, T_W_C, header.stamp.toSec());
        if (T_W_C) motion_state_ = "tracking in " + world_frame_;
      } catch (const std::exception& e) {
        out = none;
        motion_state_ = std::string("not tracked: ") + e.what() + ": every vehicle masked";
      }
    }
    for (const auto& d : out) {
      n_moving_ += d.motion == VehicleMotion::Moving;
      n_parked_ += d.motion == VehicleMotion::Parked;
      n_undecided_ += d.motion == VehicleMotion::Undecided;
    }
    return out;
  }

  // depth_masked/vehicles: each detection of the message with its decision
  // (the decisions follow the message's order: fromDetectionArrayMsg keeps it).
  void publishVehicles(const std_msgs::Header& header, const Detection2DArray& dets,
                       const std::vector<VehicleMotionTracker::Decision>& decisions, int w, int h) {
    TrackedVehicleArray out;
    out.header = header;
    out.world_frame = world_frame_;
    out.image_width = uint32_t(w);
    out.image_height = uint32_t(h);
    for (size_t i = 0; i < dets.detections.size() && i < decisions.size(); ++i) {
      TrackedVehicle v;
      v.detection = dets.detections[i];
      const auto& d = decisions[i];
      v.motion = d.motion == VehicleMotion::Moving   ? TrackedVehicle::MOVING
                 : d.motion == VehicleMotion::Parked ? TrackedVehicle::PARKED
                                                     : TrackedVehicle::UNDECIDED;
      v.masked = cfg_.mask_parked || d.motion != VehicleMotion::Parked;
      v.track_id = d.track;
      v.speed = float(d.speed);
      v.position.x = d.position.x();
      v.position.y = d.position.y();
      v.position.z = d.position.z();
      out.vehicles.push_back(v);
    }
    for (const Eigen::AlignedBox3d& g : tracker_->ghostRegions()) {
      geometry_msgs::Point lo, hi;
      lo.x = g.min().x(), lo.y = g.min().y(), lo.z = g.min().z();
      hi.x = g.max().x(), hi.y = g.max().y(), hi.z = g.max().z();
      out.carve_min.push_back(lo);
      out.carve_max.push_back(hi);
    }
    vehicles_pub_.publish(out);
  }

  // The boxes on the colour-coded depth: red moving, green parked, yellow undecided.
  static void drawDecisions(cv::Mat* colour, const std::vector<Detection>& boxes,
                            const std::vector<VehicleMotionTracker::Decision>& decisions, int w, int h) {
    const double sx = double(colour->cols) / w, sy = double(colour->rows) / h;
    for (size_t i = 0; i < boxes.size() && i < decisions.size(); ++i) {
      const Detection& b = boxes[i];
      if (!std::isfinite(b.x_min) || !std::isfinite(b.y_min) || !std::isfinite(b.x_max) || !std::isfinite(b.y_max))
        continue;
      const VehicleMotion m = decisions[i].motion;
      const cv::Scalar c = m == VehicleMotion::Moving   ? cv::Scalar(0, 0, 255)
                           : m == VehicleMotion::Parked ? cv::Scalar(0, 200, 0)
                                                        : cv::Scalar(0, 220, 255);
      const cv::Point p0(int(b.x_min * sx), int(b.y_min * sy)), p1(int(b.x_max * sx), int(b.y_max * sy));
      cv::rectangle(*colour, p0, p1, c, 2);
      std::string label = toString(m);
      if (std::isfinite(decisions[i].speed)) label += cv::format(" %.1f m/s", decisions[i].speed);
      cv::putText(*colour, label, cv::Point(p0.x, std::max(12, p0.y - 4)), cv::FONT_HERSHEY_SIMPLEX, 0.45, c, 1);
    }
  }

  DepthMaskConfig cfg_;  // the running parameters
  std::string world_frame_ = "map";
  std::unique_ptr<VehicleMotionTracker> tracker_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  ros::Publisher vehicles_pub_;
  std::optional<CameraModel> camera_;
  sensor_msgs::CameraInfoConstPtr camera_info_used_;
  std::string motion_state_ = "no vehicle yet";
  std::uint64_t n_moving_ = 0, n_parked_ = 0, n_undecided_ = 0;
  std::string transport_, info_in_topic_;
  std::unique_ptr<Pairer> pairer_;
  std::unique_ptr<StreamTimeline> timeline_;
  std::uint64_t unmasked_ = 0;
  std::mutex mutex_, connect_mutex_, info_mutex_;
  sensor_msgs::CameraInfoConstPtr info_;
  std::string info_problem_;
  bool told_no_info_ = false;
  std::optional<sensor_msgs::Image> unmatched_depth_;  // the last masked depth out before any CameraInfo (info_mutex_)
  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::Subscriber depth_sub_;
  ros::Subscriber det_sub_, info_sub_;
  image_transport::Publisher masked_pub_, mask_pub_, colour_pub_;
  ros::Publisher info_pub_;
  ros::WallTimer timer_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<ReconfigureConfig>> reconfigure_;
  std::unique_ptr<StageMonitor> monitor_;  // last: its timer stops first
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::DepthMaskNodelet, nodelet::Nodelet)
