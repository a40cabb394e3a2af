// Plane-sweep depth nodelet: the core PlaneSweep over synchronized frame sets.
//
// Topics are relative to the node's namespace (vehicle.launch: /fisheye_mapping).
// Subscribes  frames (fisheye_mapping/CameraFrameSet), only while someone
//             listens to an output (lazy, as stereo_image_proc). The frame
//             sets go through a one-set mailbox to a worker thread: a set that
//             arrives while one waits replaces it (dropped "busy").
// Publishes   through image_transport, all with the reference camera image's
//             header (stamp, frame_id):
//             depth/image      (32FC1: metres of Euclidean range along the
//                               pixel's ray, NaN invalid) with
//             depth/camera_info (the reference camera's CameraInfo: the depth
//                               image is at the camera's full resolution)
//             depth/image_z    (32FC1: REP 118 z-depth, metres along the
//                               optical axis, NaN invalid and where a ray has
//                               no forward component)
//             depth/cost       (32FC1: best matching cost (1 - ZNCC) / 2, NaN none)
//             depth/uniqueness (32FC1: best / second-best cost; ~publish_uniqueness)
// Parameters  ~camchain, ~mount (rig), ~reference_camera (cam0),
//             ~support_cameras (list; default all others), ~self_masks
//             (dict camera -> mask image path, non-zero = car body),
//             plane-sweep parameters (see config/plane_sweep_depth.yaml);
//             filter thresholds and near / far / ground_height / ground_min /
//             ground_max / min_parallax_* / min_overlap also through
//             dynamic_reconfigure (cfg/PlaneSweepFilters.cfg; the latter
//             rebuild the sweep), ~time_reset_threshold (s, default 1; 0: never).
//             /diagnostics (StageMonitor "depth"): input / output rates,
//             processing time, drops by reason ("busy", "bad input" - logged
//             with the stamp, the stage goes on), time resets, backend,
//             supporting views used.
// Time going backwards (frame-set stamps back by more than the threshold, or
// the sim clock behind the newest stamp) is logged with both stamps and
// counted; the stage keeps no other state keyed on time (each frame set is
// swept on its own, the mailbox holds one set).
#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>

#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <sensor_msgs/Image.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/PlaneSweepFiltersConfig.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/depth/depth_stage.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/ros/camera_info.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_monitor.h"

namespace fisheye_mapping {

class PlaneSweepDepthNodelet : public nodelet::Nodelet {
 public:
  ~PlaneSweepDepthNodelet() override {
    {
      std::lock_guard<std::mutex> lock(mailbox_mutex_);
      stopping_ = true;
    }
    mailbox_cv_.notify_all();
    if (worker_.joinable()) worker_.join();
  }

 private:
  // cfg/PlaneSweepFilters.cfg's level bit of the parameters that rebuild the sweep.
  static constexpr uint32_t kSweepLevel = 1;

  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    try {
      // The depth stage's parameters are declared once, in the core
      // (DepthStageConfig, PlaneSweepConfig): the offline FrameSetMapper reads
      // the same names into the same stage object.
      const DepthStageConfig config = DepthStageConfig::fromParams(RosParams(pnh));
      stage_ = std::make_unique<DepthStage>(loadRigFromParams(pnh), config);
      // Built once: per pixel, the z of the reference camera's ray.
      zdepth_ = std::make_unique<ZDepthConverter>(stage_->rig().cameras[stage_->reference()].model);
      monitor_ = std::make_unique<StageMonitor>(nh, pnh, "depth");
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
    monitor_->setExtraReport([this](diagnostic_updater::DiagnosticStatusWrapper& stat) { report(stat); });
    clock_timer_ = nh.createWallTimer(ros::WallDuration(0.2), [this](const ros::WallTimerEvent&) { checkClock(); });
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<PlaneSweepFiltersConfig>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](PlaneSweepFiltersConfig& c, uint32_t level) { onReconfigure(c, level); });
    worker_ = std::thread([this] { work(); });
    advertise(nh);
  }

  void advertise(ros::NodeHandle& nh) {
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    auto connect = [this](const image_transport::SingleSubscriberPublisher&) { updateSubscription(); };
    auto info_connect = [this](const ros::SingleSubscriberPublisher&) { updateSubscription(); };
    depth_pub_ = it_->advertiseCamera("depth/image", 2, connect, connect, info_connect, info_connect);
    z_pub_ = it_->advertise("depth/image_z", 2, connect, connect);
    cost_pub_ = it_->advertise("depth/cost", 2, connect, connect);
    if (publish_uniqueness_) uniqueness_pub_ = it_->advertise("depth/uniqueness", 2, connect, connect);
  }

  // The names are the core's (PlaneSweepConfig::fromParams, checked against
  // cfg/PlaneSweepFilters.cfg by test_reconfigure_params). Filters change in
  // place; the planes and view thresholds (level kSweepLevel) rebuild the
  // sweep, except on the first call: its values are the start-up parameters
  // the stage was built from.
  void onReconfigure(PlaneSweepFiltersConfig& c, uint32_t level) {
    c.consistency_window |= 1;  // odd windows only
    dynamic_reconfigure::Config values;
    c.__toMessage__(values);
    std::lock_guard<std::mutex> lock(mutex_);
    try {
      // Over the running sweep: what the .cfg does not hold (min_noise_std, planes, windows) stays.
      const PlaneSweepConfig next = PlaneSweepConfig::fromParams(ReconfigureParams(values), stage_->sweepConfig());
      if ((level & kSweepLevel) && reconfigured_) {
        stage_->setSweepConfig(next);
        NODELET_INFO("sweep rebuilt: near %.2f, far %.1f m, ground %.2f + [%.2f, %.2f] m, min parallax %.3f px",
                     next.near, next.far, next.ground_height, next.ground_min, next.ground_max, next.min_parallax_px);
      } else {
        stage_->setFilters(next.filters);
      }
      reconfigured_ = true;
    } catch (const std::exception& e) {
      monitor_->error(std::string("sweep parameters rejected: ") + e.what());
      NODELET_ERROR("sweep parameters rejected: %s", e.what());
    }
  }

  void updateSubscription() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    const bool wanted = depth_pub_.getNumSubscribers() > 0 || z_pub_.getNumSubscribers() > 0 ||
                        cost_pub_.getNumSubscribers() > 0 ||
                        (publish_uniqueness_ && uniqueness_pub_.getNumSubscribers() > 0);
    try {
      if (wanted && !sub_) {
        sub_ = getNodeHandle().subscribe("frames", 2, &PlaneSweepDepthNodelet::onFrames, this);
      } else if (!wanted && sub_) {
        sub_.shutdown();
      }
      monitor_->setInputExpected(wanted);
    } catch (const std::exception& e) {
      monitor_->error(std::string("subscribing: ") + e.what());
      NODELET_ERROR("cannot subscribe the frame sets: %s", e.what());
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
    monitor_->timeReset(formatStamp(ev.from_ns) + " s -> " + formatStamp(ev.to_ns) + " s: " + ev.reason);
  }

  void report(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    stat.add("backend", stage_->backendName());
    stat.add("reference camera", stage_->rig().cameras[stage_->reference()].name);
    std::lock_guard<std::mutex> lock(views_mutex_);
    stat.add("supporting views used", used_views_);
  }

  // The subscription's callback: into the mailbox, replacing a set that still
  // waits (the sweep is slower than the frames: the newest set wins).
  void onFrames(const CameraFrameSetConstPtr& set) {
    monitor_->input();
    {
      std::lock_guard<std::mutex> tl(time_mutex_);
      const auto ev = timeline_->observe(0, std::int64_t(set->header.stamp.toNSec()));
      if (ev.kind == StreamTimeline::Kind::kReset) onTimeReset(ev);
    }
    {
      std::lock_guard<std::mutex> lock(mailbox_mutex_);
      if (mailbox_) monitor_->dropped("busy");
      mailbox_ = set;
    }
    mailbox_cv_.notify_one();
  }

  void work() {
    for (;;) {
      CameraFrameSetConstPtr set;
      {
        std::unique_lock<std::mutex> lock(mailbox_mutex_);
        mailbox_cv_.wait(lock, [this] { return stopping_ || mailbox_; });
        if (stopping_) return;
        set.swap(mailbox_);
      }
      std::lock_guard<std::mutex> lock(mutex_);
      const double t0 = StageStats::now();
      try {
        process(*set, set);
        monitor_->output();
      } catch (const std::exception& e) {
        skip(*set, e.what());
      } catch (...) {
        skip(*set, "unknown exception");
      }
      monitor_->processed(StageStats::now() - t0);
    }
  }

  void skip(const CameraFrameSet& set, const std::string& what) {
    monitor_->dropped("bad input");
    monitor_->error("frame set at " + formatStamp(std::int64_t(set.header.stamp.toNSec())) + ": " + what);
    NODELET_ERROR_THROTTLE(0.2, "frame set at %.3f skipped: %s", set.header.stamp.toSec(), what.c_str());
  }

  // Rig camera i's image of the set (aliasing the set's lifetime), or nullptr.
  sensor_msgs::ImageConstPtr imageOf(const CameraFrameSet& set, const CameraFrameSetConstPtr& owner, int cam) const {
    for (size_t i = 0; i < set.camera_names.size(); ++i) {
      if (set.camera_names[i] == stage_->rig().cameras[cam].name) return sensor_msgs::ImageConstPtr(owner, &set.images[i]);
    }
    return nullptr;
  }

  void process(const CameraFrameSet& set, const CameraFrameSetConstPtr& owner) {
    if (set.camera_names.size() != set.images.size()) {
      throw std::invalid_argument("frame set has " + std::to_string(set.camera_names.size()) + " names but " +
                                  std::to_string(set.images.size()) + " images");
    }
    const Rig& rig = stage_->rig();
    const int ref = stage_->reference();
    const sensor_msgs::ImageConstPtr ref_img = imageOf(set, owner, ref);
    if (!ref_img) throw std::invalid_argument("frame set has no image of the reference camera " + rig.cameras[ref].name);
    std::vector<cv::Mat> images(rig.cameras.size());  // empty: not in the set (DepthStage names it)
    images[ref] = toCvImageShare(ref_img, ImageTarget::kSweep, rig.cameras[ref].name);
    for (int i : stage_->supports()) {
      if (const sensor_msgs::ImageConstPtr img = imageOf(set, owner, i)) {
        images[i] = toCvImageShare(img, ImageTarget::kSweep, rig.cameras[i].name);
      }
    }
    const DepthResult r = stage_->compute(images);
    if (!r.dropped_views.empty()) NODELET_INFO_ONCE("supporting view dropped: %s", r.dropped_views.front().c_str());
    for (const auto& w : r.warnings) NODELET_WARN_THROTTLE(10.0, "frame %.3f: %s", ref_img->header.stamp.toSec(), w.c_str());
    {
      std::lock_guard<std::mutex> lock(views_mutex_);
      used_views_.clear();
      for (const auto& v : r.used_views) used_views_ += (used_views_.empty() ? "" : " ") + v;
    }
    std_msgs::Header header = ref_img->header;
    if (header.frame_id.empty()) header.frame_id = rig.cameras[ref].frame_id;
    publish(header, r);
    NODELET_DEBUG("depth in %.1f ms (sweep %.1f, filters %.1f)", r.total_ms, r.sweep_ms, r.filter_ms);
  }

  void publish(const std_msgs::Header& header, const DepthResult& r) {
    sensor_msgs::CameraInfo info = toCameraInfo(stage_->rig().cameras[stage_->reference()], header.stamp);
    info.header = header;
    depth_pub_.publish(*toDepthMsg(header, r.depth), info);
    if (z_pub_.getNumSubscribers() > 0) z_pub_.publish(toDepthMsg(header, zdepth_->convert(r.depth)));
    cost_pub_.publish(toImageMsg(header, r.cost));  // 32FC1
    if (publish_uniqueness_) uniqueness_pub_.publish(toImageMsg(header, r.uniqueness));
  }

  std::unique_ptr<DepthStage> stage_;
  std::unique_ptr<ZDepthConverter> zdepth_;
  bool publish_uniqueness_ = false, reconfigured_ = false;
  std::mutex mutex_, connect_mutex_;  // mutex_: the stage (worker, reconfigure)
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<PlaneSweepFiltersConfig>> reconfigure_;
  ros::Subscriber sub_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::CameraPublisher depth_pub_;
  image_transport::Publisher z_pub_, cost_pub_, uniqueness_pub_;
  std::mutex time_mutex_;
  std::unique_ptr<StreamTimeline> timeline_;
  std::unique_ptr<StageMonitor> monitor_;
  ros::WallTimer clock_timer_;
  std::mutex views_mutex_;
  std::string used_views_;
  // The mailbox: the newest frame set not yet swept.
  std::mutex mailbox_mutex_;
  std::condition_variable mailbox_cv_;
  CameraFrameSetConstPtr mailbox_;
  bool stopping_ = false;
  std::thread worker_;  // last: joined in the destructor before the rest goes
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::PlaneSweepDepthNodelet, nodelet::Nodelet)
