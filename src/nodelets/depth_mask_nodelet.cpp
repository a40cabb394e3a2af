// Depth mask nodelet: removes potentially moving objects from depth maps
// before fusion (paper Sec. III-B).
//
// Subscribes  depth      (sensor_msgs/Image 32FC1, range along the ray, NaN invalid)
//             detections (fisheye_mapping/Detection2DArray of the same camera)
//             while someone listens to an output (lazy).
// Publishes   depth_masked (32FC1: NaN inside every box grown by ~margin_px)
//             depth_mask   (mono8: 255 where a box removed depth)
//             depth_masked_colour (bgr8: colour-coded masked depth, black
//                          invalid; only while subscribed; ~colour_range [near, far])
//             all with the depth map's header.
// Pairing     by exact stamp. A depth map waits up to ~wait_for_detections
//             seconds (wall time) for its detections; then it passes through
//             unmasked and the count of such frames is reported (warning).
//             A frame whose detections are empty passes unchanged.
// Parameters  ~margin_px (default 10), ~wait_for_detections (default 0.5 s),
//             ~max_pending (default 30 depth maps / detection sets),
//             ~time_reset_threshold (s, default 1; 0: never).
// Time going backwards (depth or detection stamps back by more than the
// threshold on their own stream, or the sim clock behind the newest stamp):
// the pairing state, keyed on stamps, is cleared (depth maps still waiting are
// dropped, not published: they belong to the old timeline; so are depth maps
// and detections of the old timeline still in flight), with a warning naming
// both stamps. Without it, a bag played twice would find its detections
// "late" (their stamps were released in the first play) and pass every depth
// map unmasked.
// /diagnostics: depth in, masked out, passed unmasked, late detections, time
// resets, dropped at a reset, callback errors (WARN for a while after a reset
// or an error; WARN while depth maps pass unmasked).
#include <atomic>
#include <memory>
#include <mutex>

#include <diagnostic_updater/diagnostic_updater.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <sensor_msgs/Image.h>

#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/detection/depth_mask.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_health.h"

namespace fisheye_mapping {

class DepthMaskNodelet : public nodelet::Nodelet {
 private:
  using Pairer = StampPairer<sensor_msgs::ImageConstPtr, Detection2DArrayConstPtr>;

  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    // Every masking parameter is declared once, in the core (DepthMaskConfig).
    DepthMaskConfig cfg;
    try {
      cfg = DepthMaskConfig::fromParams(RosParams(pnh));
    } catch (const std::exception& e) {
      health_.error(std::string("parameters rejected, defaults used: ") + e.what());
      NODELET_ERROR("depth mask parameters rejected, using the defaults: %s", e.what());
    }
    const double wait = cfg.wait_for_detections;
    const double time_reset = cfg.time_reset_threshold;
    margin_px_ = cfg.margin_px;
    colour_near_ = cfg.colour_near, colour_far_ = cfg.colour_far;
    wait_ = wait;
    max_pending_ = std::size_t(cfg.max_pending);
    pairer_ = std::make_unique<Pairer>(wait_, max_pending_);
    timeline_ = std::make_unique<StreamTimeline>(2, time_reset);
    diag_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, getName());
    diag_->setHardwareID("depth mask");
    diag_->add("masking", this, &DepthMaskNodelet::diagnose);
    diag_timer_ = nh.createWallTimer(ros::WallDuration(1.0), [this](const ros::WallTimerEvent&) {
      try {
        diag_->force_update();
      } catch (const std::exception& e) {
        health_.error(std::string("diagnostics: ") + e.what());
      }
    });
    auto connect = [this](const ros::SingleSubscriberPublisher&) { updateSubscription(); };
    masked_pub_ = nh.advertise<sensor_msgs::Image>("depth_masked", 5, connect, connect);
    mask_pub_ = nh.advertise<sensor_msgs::Image>("depth_mask", 5, connect, connect);
    colour_pub_ = nh.advertise<sensor_msgs::Image>("depth_masked_colour", 2, connect, connect);
    timer_ = nh.createWallTimer(ros::WallDuration(std::max(0.005, std::min(0.05, wait / 4))),
                                [this](const ros::WallTimerEvent&) { onTimer(); });
    NODELET_INFO("depth mask: margin %.1f px, waits %.3f s for detections", margin_px_, wait);
  }

  void updateSubscription() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    try {
      subscribeIfWanted();
    } catch (const std::exception& e) {
      health_.error(std::string("subscribing: ") + e.what());
      NODELET_ERROR("cannot subscribe depth / detections: %s", e.what());
    }
  }

  void subscribeIfWanted() {
    const bool wanted = masked_pub_.getNumSubscribers() > 0 || mask_pub_.getNumSubscribers() > 0 ||
                        colour_pub_.getNumSubscribers() > 0;
    if (wanted && !depth_sub_) {
      depth_sub_ = getNodeHandle().subscribe("depth", 5, &DepthMaskNodelet::onDepth, this);
      det_sub_ = getNodeHandle().subscribe("detections", 10, &DepthMaskNodelet::onDetections, this);
    } else if (!wanted && depth_sub_) {
      depth_sub_.shutdown();
      det_sub_.shutdown();
    }
  }

  static double now() { return ros::WallTime::now().toSec(); }

  enum Stream { kDepth = 0, kDetections = 1 };

  // The stamp on its stream's timeline; false: a straggler of an old timeline (dropped).
  bool onTimeline(Stream stream, const ros::Time& stamp) {
    const auto ev = timeline_->observe(stream, std::int64_t(stamp.toNSec()));
    if (ev.kind == StreamTimeline::Kind::kStale) {
      ++stale_;
      return false;
    }
    if (ev.kind == StreamTimeline::Kind::kReset) resetTime(ev, stream == kDepth ? "depth" : "detections");
    return true;
  }

  // Called with mutex_ held.
  void resetTime(const StreamTimeline::Event& ev, const char* what) {
    const std::size_t dropped = pairer_->pendingDepth();
    dropped_at_reset_ += dropped;
    // Counts carry over (they are reported as totals).
    timed_out_before_ += pairer_->timedOut();
    late_before_ += pairer_->late();
    pairer_ = std::make_unique<Pairer>(wait_, max_pending_);
    NODELET_WARN("depth mask: time went backwards (%s) from %s s to %s s (%s); pairing reset, %zu waiting depth "
                 "map(s) dropped", what, formatStamp(ev.from_ns).c_str(), formatStamp(ev.to_ns).c_str(),
                 ev.reason.c_str(), dropped);
    health_.timeReset(std::string(what) + " " + formatStamp(ev.from_ns) + " s -> " + formatStamp(ev.to_ns) +
                      " s: " + ev.reason);
  }

  template <class F>
  void guarded(const char* what, const ros::Time& stamp, F&& f) {
    try {
      f();
    } catch (const std::exception& e) {
      health_.error(std::string(what) + " at " + formatStamp(std::int64_t(stamp.toNSec())) + ": " + e.what());
      NODELET_ERROR_THROTTLE(1.0, "%s at %.3f skipped: %s", what, stamp.toSec(), e.what());
    } catch (...) {
      health_.error(std::string(what) + " at " + formatStamp(std::int64_t(stamp.toNSec())) + ": unknown exception");
      NODELET_ERROR_THROTTLE(1.0, "%s at %.3f skipped: unknown exception", what, stamp.toSec());
    }
  }

  void onDepth(const sensor_msgs::ImageConstPtr& msg) {
    ++depth_in_;
    try {
      checkDepthImage(*msg, getNodeHandle().resolveName("depth"));
    } catch (const ImageConversionError& e) {
      health_.error("depth at " + formatStamp(std::int64_t(msg->header.stamp.toNSec())) + ": " + e.what());
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
      const auto late = pairer_->late();
      publish(pairer_->addDetections(msg->header.stamp.toNSec(), msg, now()));
      if (pairer_->late() != late)
        NODELET_WARN_THROTTLE(5.0, "detections at %.3f came after their depth map had passed through (%lu so far)",
                              msg->header.stamp.toSec(), (unsigned long)(late_before_ + pairer_->late()));
    });
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

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    std::lock_guard<std::mutex> lock(mutex_);
    stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "masking");
    const std::uint64_t unmasked = timed_out_before_ + pairer_->timedOut();
    stat.add("depth maps in", depth_in_.load());
    stat.add("masked depth out", masked_out_);
    stat.add("passed unmasked (no detections in time)", unmasked);
    stat.add("late detections", late_before_ + pairer_->late());
    stat.add("waiting depth maps dropped at a time reset", dropped_at_reset_);
    stat.add("stale messages dropped (old timeline)", stale_);
    if (unmasked > last_unmasked_)
      stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, "depth maps passed unmasked (no detections in time)");
    last_unmasked_ = unmasked;
    health_.report(stat);
  }

  void publish(const std::vector<Pairer::Pair>& pairs) {
    for (const auto& p : pairs) {
      try {
        cv::Mat depth = toDepth(*p.depth);
        std::vector<Detection> boxes;
        int w = depth.cols, h = depth.rows;
        if (p.dets) {
          StampedDetections d = fromDetectionArrayMsg(**p.dets);
          if (d.image_width > 0 && d.image_height > 0) w = d.image_width, h = d.image_height;
          boxes = std::move(d.detections);
        } else {
          NODELET_WARN_THROTTLE(5.0, "no detections for depth at %.3f within the wait; passed through unmasked "
                                "(%lu so far)", p.depth->header.stamp.toSec(),
                                (unsigned long)(timed_out_before_ + pairer_->timedOut()));
        }
        const cv::Mat mask = maskDepthBoxes(depth, boxes, float(margin_px_), w, h);
        ++masked_out_;
        masked_pub_.publish(toDepthMsg(p.depth->header, depth));
        mask_pub_.publish(toImageMsg(p.depth->header, mask));  // mono8
        if (colour_pub_.getNumSubscribers() > 0)
          colour_pub_.publish(toImageMsg(p.depth->header, colorizeDepth(depth, colour_near_, colour_far_)));  // bgr8
      } catch (const std::exception& e) {
        health_.error("depth at " + formatStamp(std::int64_t(p.depth->header.stamp.toNSec())) + ": " + e.what());
        NODELET_ERROR_THROTTLE(1.0, "depth at %.3f skipped: %s", p.depth->header.stamp.toSec(), e.what());
      } catch (...) {
        health_.error("depth at " + formatStamp(std::int64_t(p.depth->header.stamp.toNSec())) + ": unknown exception");
        NODELET_ERROR_THROTTLE(1.0, "depth at %.3f skipped: unknown exception", p.depth->header.stamp.toSec());
      }
    }
  }

  double margin_px_ = 10.0, colour_near_ = 1.0, colour_far_ = 30.0;
  std::unique_ptr<Pairer> pairer_;
  double wait_ = 0.5;
  std::size_t max_pending_ = 30;
  std::unique_ptr<StreamTimeline> timeline_;
  StageHealth health_;
  std::unique_ptr<diagnostic_updater::Updater> diag_;
  ros::WallTimer diag_timer_;
  std::atomic<std::uint64_t> depth_in_{0};
  std::uint64_t masked_out_ = 0, dropped_at_reset_ = 0, stale_ = 0, timed_out_before_ = 0, late_before_ = 0,
                last_unmasked_ = 0;
  std::mutex mutex_, connect_mutex_;
  ros::Subscriber depth_sub_, det_sub_;
  ros::Publisher masked_pub_, mask_pub_, colour_pub_;
  ros::WallTimer timer_;
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::DepthMaskNodelet, nodelet::Nodelet)
