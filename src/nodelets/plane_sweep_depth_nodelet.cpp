// Plane-sweep depth nodelet: the core PlaneSweep over synchronized frame sets.
//
// Subscribes  frames (fisheye_mapping/CameraFrameSet), only while someone
//             listens to an output (lazy, as stereo_image_proc)
// Publishes   depth      (sensor_msgs/Image 32FC1: metres of Euclidean range
//                         along the pixel's ray, NaN invalid)
//             cost       (32FC1: best matching cost (1 - ZNCC) / 2, NaN none)
//             uniqueness (32FC1: best / second-best cost; ~publish_uniqueness)
//             all with the reference camera image's header (stamp, frame_id).
// Parameters  ~camchain, ~mount (rig), ~reference_camera (cam0),
//             ~support_cameras (list; default all others), ~self_masks
//             (dict camera -> mask image path, non-zero = car body),
//             plane-sweep parameters (see config/plane_sweep_depth.yaml);
//             filter thresholds also through dynamic_reconfigure,
//             ~time_reset_threshold (s, default 1; 0: never).
//             /diagnostics: frame sets in, depth maps out, mean time, frame
//             sets skipped (an error: logged with the stamp, the stage goes on),
//             time resets (WARN for a while after either).
// Time going backwards (frame-set stamps back by more than the threshold, or
// the sim clock behind the newest stamp) is logged with both stamps and
// counted; the stage keeps no other state keyed on time (each frame set is
// swept on its own, the subscription queue holds one set).
#include <atomic>
#include <memory>
#include <mutex>

#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <nodelet/nodelet.h>
#include <opencv2/imgcodecs.hpp>
#include <pluginlib/class_list_macros.hpp>
#include <sensor_msgs/Image.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/PlaneSweepFiltersConfig.h"
#include "fisheye_mapping/core/depth/depth_stage.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_health.h"

namespace fisheye_mapping {

class PlaneSweepDepthNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    try {
      // The depth stage's parameters are declared once, in the core
      // (DepthStageConfig, PlaneSweepConfig): the offline FrameSetMapper reads
      // the same names into the same stage object.
      const DepthStageConfig config = DepthStageConfig::fromParams(RosParams(pnh));
      stage_ = std::make_unique<DepthStage>(loadRigFromParams(pnh), config);
      NODELET_INFO("plane sweep on %s, reference %s, %zu supporting camera(s), %s", stage_->backendName().c_str(),
                   config.reference_camera.c_str(), stage_->supports().size(),
                   toString(config.sweep.resolution).c_str());
    } catch (const std::exception& e) {
      NODELET_FATAL("plane sweep depth not started: %s", e.what());
      return;
    }
    pnh.param("publish_uniqueness", publish_uniqueness_, false);
    double time_reset = 1.0;
    pnh.param("time_reset_threshold", time_reset, time_reset);
    timeline_ = std::make_unique<StreamTimeline>(1, time_reset);
    diag_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, getName());
    diag_->setHardwareID("plane sweep (" + stage_->backendName() + ")");
    diag_->add("depth", this, &PlaneSweepDepthNodelet::diagnose);
    diag_timer_ = nh.createWallTimer(ros::WallDuration(1.0), [this](const ros::WallTimerEvent&) {
      try {
        diag_->force_update();
      } catch (const std::exception& e) {
        health_.error(std::string("diagnostics: ") + e.what());
      }
    });
    clock_timer_ = nh.createWallTimer(ros::WallDuration(0.2), [this](const ros::WallTimerEvent&) { checkClock(); });
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<PlaneSweepFiltersConfig>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](PlaneSweepFiltersConfig& c, uint32_t) { onReconfigure(c); });

    auto connect = [this](const ros::SingleSubscriberPublisher&) { updateSubscription(); };
    depth_pub_ = nh.advertise<sensor_msgs::Image>("depth", 2, connect, connect);
    cost_pub_ = nh.advertise<sensor_msgs::Image>("cost", 2, connect, connect);
    if (publish_uniqueness_) uniqueness_pub_ = nh.advertise<sensor_msgs::Image>("uniqueness", 2, connect, connect);
  }

  // The filter names are the core's (DepthFilterConfig::fromParams, checked
  // against cfg/PlaneSweepFilters.cfg by test_reconfigure_params).
  void onReconfigure(PlaneSweepFiltersConfig& c) {
    c.consistency_window |= 1;  // odd windows only
    dynamic_reconfigure::Config values;
    c.__toMessage__(values);
    std::lock_guard<std::mutex> lock(mutex_);
    try {
      // Over the running filters: what the .cfg does not hold (min_noise_std) stays.
      stage_->setFilters(DepthFilterConfig::fromParams(ReconfigureParams(values), stage_->sweepConfig().filters));
    } catch (const std::exception& e) {
      health_.error(std::string("filter parameters rejected: ") + e.what());
      NODELET_ERROR("filter parameters rejected: %s", e.what());
    }
  }

  void updateSubscription() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    try {
      subscribeIfWanted();
    } catch (const std::exception& e) {
      health_.error(std::string("subscribing: ") + e.what());
      NODELET_ERROR("cannot subscribe the frame sets: %s", e.what());
    }
  }

  void subscribeIfWanted() {
    const bool wanted = depth_pub_.getNumSubscribers() > 0 || cost_pub_.getNumSubscribers() > 0 ||
                        (publish_uniqueness_ && uniqueness_pub_.getNumSubscribers() > 0);
    if (wanted && !sub_) {
      sub_ = getNodeHandle().subscribe("frames", 1, &PlaneSweepDepthNodelet::onFrames, this);
    } else if (!wanted && sub_) {
      sub_.shutdown();
    }
  }

  void checkClock() {
    const std::int64_t now = simClockNs();
    if (!now) return;
    std::lock_guard<std::mutex> lock(time_mutex_);
    if (auto ev = timeline_->clock(now)) onTimeReset(*ev);
  }

  void onTimeReset(const StreamTimeline::Event& ev) {
    NODELET_WARN("plane sweep: time went backwards from %s s to %s s (%s); depth stage time state reset",
                 formatStamp(ev.from_ns).c_str(), formatStamp(ev.to_ns).c_str(), ev.reason.c_str());
    health_.timeReset(formatStamp(ev.from_ns) + " s -> " + formatStamp(ev.to_ns) + " s: " + ev.reason);
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "sweeping");
    const std::uint64_t in = frames_in_, out = depth_out_;
    stat.add("frame sets in", in);
    stat.add("depth maps out", out);
    stat.add("frame sets skipped", skipped_.load());
    stat.addf("mean depth time (ms)", "%.1f", out ? total_ms_ / out : 0.0);
    health_.report(stat);
  }

  void onFrames(const CameraFrameSetConstPtr& set) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!stage_) return;
    ++frames_in_;
    {
      std::lock_guard<std::mutex> tl(time_mutex_);
      const auto ev = timeline_->observe(0, std::int64_t(set->header.stamp.toNSec()));
      if (ev.kind == StreamTimeline::Kind::kReset) onTimeReset(ev);
    }
    try {
      if (set->camera_names.size() != set->images.size()) {
        throw std::invalid_argument("frame set has " + std::to_string(set->camera_names.size()) + " names but " +
                                    std::to_string(set->images.size()) + " images");
      }
      auto find = [&](int cam) -> sensor_msgs::ImageConstPtr {
        for (size_t i = 0; i < set->camera_names.size(); ++i) {
          if (set->camera_names[i] == stage_->rig().cameras[cam].name) {
            return sensor_msgs::ImageConstPtr(set, &set->images[i]);  // aliases the set's lifetime
          }
        }
        return nullptr;
      };
      const Rig& rig = stage_->rig();
      const int ref = stage_->reference();
      const sensor_msgs::ImageConstPtr ref_img = find(ref);
      if (!ref_img) throw std::invalid_argument("frame set has no image of the reference camera " + rig.cameras[ref].name);
      std::vector<cv::Mat> images(rig.cameras.size());  // empty: not in the set (DepthStage names it)
      images[ref] = toCvImageShare(ref_img, ImageTarget::kSweep, rig.cameras[ref].name);
      for (int i : stage_->supports()) {
        if (const sensor_msgs::ImageConstPtr img = find(i)) {
          images[i] = toCvImageShare(img, ImageTarget::kSweep, rig.cameras[i].name);
        }
      }
      const DepthResult r = stage_->compute(images);
      if (!r.dropped_views.empty()) NODELET_INFO_ONCE("supporting view dropped: %s", r.dropped_views.front().c_str());
      for (const auto& w : r.warnings) NODELET_WARN_THROTTLE(10.0, "frame %.3f: %s", ref_img->header.stamp.toSec(), w.c_str());
      std_msgs::Header header = ref_img->header;
      if (header.frame_id.empty()) header.frame_id = rig.cameras[ref].frame_id;
      depth_pub_.publish(toDepthMsg(header, r.depth));
      cost_pub_.publish(toImageMsg(header, r.cost));  // 32FC1
      if (publish_uniqueness_) uniqueness_pub_.publish(toImageMsg(header, r.uniqueness));
      NODELET_DEBUG("depth in %.1f ms (sweep %.1f, filters %.1f)", r.total_ms, r.sweep_ms, r.filter_ms);
      total_ms_ = total_ms_ + r.total_ms;
      ++depth_out_;
    } catch (const std::exception& e) {
      ++skipped_;
      health_.error("frame set at " + formatStamp(std::int64_t(set->header.stamp.toNSec())) + ": " + e.what());
      NODELET_ERROR_THROTTLE(0.2, "frame set at %.3f skipped: %s", set->header.stamp.toSec(), e.what());
    } catch (...) {
      ++skipped_;
      health_.error("frame set at " + formatStamp(std::int64_t(set->header.stamp.toNSec())) + ": unknown exception");
      NODELET_ERROR_THROTTLE(0.2, "frame set at %.3f skipped: unknown exception", set->header.stamp.toSec());
    }
  }

  std::unique_ptr<DepthStage> stage_;
  bool publish_uniqueness_ = false;
  std::mutex mutex_, connect_mutex_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<PlaneSweepFiltersConfig>> reconfigure_;
  ros::Subscriber sub_;
  ros::Publisher depth_pub_, cost_pub_, uniqueness_pub_;
  std::mutex time_mutex_;
  std::unique_ptr<StreamTimeline> timeline_;
  StageHealth health_;
  std::unique_ptr<diagnostic_updater::Updater> diag_;
  ros::WallTimer diag_timer_, clock_timer_;
  std::atomic<std::uint64_t> frames_in_{0}, depth_out_{0}, skipped_{0};
  std::atomic<double> total_ms_{0.0};
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::PlaneSweepDepthNodelet, nodelet::Nodelet)
