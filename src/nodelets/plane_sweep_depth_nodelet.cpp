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

#include <cv_bridge/cv_bridge.h>
#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <nodelet/nodelet.h>
#include <opencv2/imgcodecs.hpp>
#include <pluginlib/class_list_macros.hpp>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/PlaneSweepFiltersConfig.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_health.h"

namespace fisheye_mapping {

namespace enc = sensor_msgs::image_encodings;

class PlaneSweepDepthNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    try {
      rig_ = loadRigFromParams(pnh);
      const PlaneSweepConfig config = loadPlaneSweepConfig(pnh);
      std::string ref_name = "cam0";
      pnh.param("reference_camera", ref_name, ref_name);
      ref_ = rig_.indexOf(ref_name);
      if (ref_ < 0) throw CalibrationError("~reference_camera: no camera '" + ref_name + "' in the rig");
      std::vector<std::string> support_names;
      if (!pnh.getParam("support_cameras", support_names)) {
        for (const auto& c : rig_.cameras) {
          if (c.name != ref_name) support_names.push_back(c.name);
        }
      }
      for (const auto& n : support_names) {
        const int i = rig_.indexOf(n);
        if (i < 0 || i == ref_) throw CalibrationError("~support_cameras: '" + n + "' is not a supporting camera of the rig");
        supports_.push_back(i);
      }
      std::map<std::string, std::string> masks;
      pnh.getParam("self_masks", masks);
      masks_.resize(rig_.cameras.size());
      for (const auto& [name, path] : masks) {
        const int i = rig_.indexOf(name);
        if (i < 0) throw CalibrationError("~self_masks: no camera '" + name + "' in the rig");
        masks_[i] = cv::imread(path, cv::IMREAD_GRAYSCALE);
        if (masks_[i].empty()) throw CalibrationError("~self_masks: cannot read " + path);
      }
      sweep_ = std::make_unique<PlaneSweep>(config);
      NODELET_INFO("plane sweep on %s, reference %s, %zu supporting camera(s), %s",
                   sweep_->backendName().c_str(), ref_name.c_str(), supports_.size(), config.resolution.c_str());
    } catch (const std::exception& e) {
      NODELET_FATAL("plane sweep depth not started: %s", e.what());
      return;
    }
    pnh.param("publish_uniqueness", publish_uniqueness_, false);
    double time_reset = 1.0;
    pnh.param("time_reset_threshold", time_reset, time_reset);
    timeline_ = std::make_unique<StreamTimeline>(1, time_reset);
    diag_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, getName());
    diag_->setHardwareID("plane sweep (" + sweep_->backendName() + ")");
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

  void onReconfigure(PlaneSweepFiltersConfig& c) {
    DepthFilterConfig f;
    f.texture = c.filter_texture;
    f.min_texture_snr = c.min_texture_snr;
    f.cost = c.filter_cost;
    f.alpha_upper = c.alpha_upper;
    f.alpha_lower = c.alpha_lower;
    f.split_row = c.split_row;
    f.uniqueness = c.filter_uniqueness;
    f.max_ratio = c.max_ratio;
    f.consistency = c.filter_consistency;
    c.consistency_window |= 1;  // odd windows only
    f.consistency_window = c.consistency_window;
    f.gamma = c.gamma;
    f.delta = c.delta;
    std::lock_guard<std::mutex> lock(mutex_);
    f.min_noise_std = sweep_->config().filters.min_noise_std;  // not reconfigurable
    try {
      sweep_->setFilters(f);
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

  // Grey or colour image as the core takes it; throws naming the problem.
  static cv::Mat toCv(const sensor_msgs::ImageConstPtr& msg, const std::string& name) {
    const std::string& e = msg->encoding;
    if (e == enc::MONO8 || e == enc::MONO16 || e == enc::TYPE_32FC1) return cv_bridge::toCvShare(msg)->image;
    if (e == enc::BGR8 || e == enc::RGB8 || e == enc::BGRA8 || e == enc::RGBA8) {
      return cv_bridge::toCvShare(msg, enc::BGR8)->image;
    }
    throw std::invalid_argument(name + ": unsupported encoding '" + e + "' (mono8, mono16, 32FC1 or 8-bit colour)");
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
    if (!sweep_) return;
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
          if (set->camera_names[i] == rig_.cameras[cam].name) {
            return sensor_msgs::ImageConstPtr(set, &set->images[i]);  // aliases the set's lifetime
          }
        }
        return nullptr;
      };
      const sensor_msgs::ImageConstPtr ref_img = find(ref_);
      if (!ref_img) throw std::invalid_argument("frame set has no image of the reference camera " + rig_.cameras[ref_].name);
      const SweepView ref = rigSweepView(rig_, ref_, ref_, toCv(ref_img, rig_.cameras[ref_].name), masks_[ref_]);
      std::vector<SweepView> views;
      for (int i : supports_) {
        const sensor_msgs::ImageConstPtr img = find(i);
        if (!img) {
          NODELET_WARN_THROTTLE(5.0, "frame set has no image of %s; sweeping without it", rig_.cameras[i].name.c_str());
          continue;
        }
        views.push_back(rigSweepView(rig_, i, ref_, toCv(img, rig_.cameras[i].name), masks_[i]));
      }
      const Eigen::Isometry3d T_base_ref = rig_.cameras[ref_].T_base_cam;
      const DepthResult r = sweep_->compute(ref, views, &T_base_ref);
      if (!r.dropped_views.empty()) NODELET_INFO_ONCE("supporting view dropped: %s", r.dropped_views.front().c_str());
      for (const auto& w : r.warnings) NODELET_WARN_THROTTLE(10.0, "frame %.3f: %s", ref_img->header.stamp.toSec(), w.c_str());
      std_msgs::Header header = ref_img->header;
      if (header.frame_id.empty()) header.frame_id = rig_.cameras[ref_].frame_id;
      depth_pub_.publish(cv_bridge::CvImage(header, enc::TYPE_32FC1, r.depth).toImageMsg());
      cost_pub_.publish(cv_bridge::CvImage(header, enc::TYPE_32FC1, r.cost).toImageMsg());
      if (publish_uniqueness_) uniqueness_pub_.publish(cv_bridge::CvImage(header, enc::TYPE_32FC1, r.uniqueness).toImageMsg());
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

  Rig rig_;
  int ref_ = 0;
  std::vector<int> supports_;
  std::vector<cv::Mat> masks_;
  std::unique_ptr<PlaneSweep> sweep_;
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
