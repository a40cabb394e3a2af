// Depth nodelet (fisheye_mapping/Depth): the core DepthStage (plane sweep,
// filters, online rotation self-calibration) over synchronized frame sets.
//
// Its topics (relative to the node's namespace), services, parameters and
// diagnostics: docs/nodelets.md#fisheye_mappingdepth; every parameter:
// docs/parameters.md.
// - frames are read only while an output has a subscriber; they go through a
//   mailbox of ~input_queue sets (default 1) to a worker thread (a newer set
//   replaces the oldest waiting one when it is full: dropped "busy").
// - depth/image (range along the ray), depth/image_z, depth/cost,
//   depth/uniqueness and depth/camera_info carry the reference image's header;
//   depth/self_calibration is latched after each self-calibration update.
// - ~save_calibration writes the self-calibrated camchain inside
//   ~save_directory (core/common/safe_write.h); the same save runs on shutdown
//   when a correction was applied.
// - With ~rig_source camera_info the rig comes from the frame sets'
//   CameraInfos and tf, rebuilt only when they change ("no rig yet" until then).
// - Time going backwards (stamps, or the sim clock behind the newest stamp) is
//   logged and counted; each frame set is swept on its own, so no other state
//   is keyed on time.
#include <algorithm>
#include <memory>
#include <mutex>
#include <optional>

#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <sensor_msgs/Image.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/FilePath.h"
#include "fisheye_mapping/DepthReconfigureConfig.h"
#include "fisheye_mapping/RigSelfCalibration.h"
#include "fisheye_mapping/core/common/latest_worker.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/depth/depth_stage.h"
#include "fisheye_mapping/ros/camera_info.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/node_options.h"
#include "fisheye_mapping/ros/nodelet_glue.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_messages.h"
#include "fisheye_mapping/ros/stage_monitor.h"
#include "fisheye_mapping/ros/tsdf_node_helpers.h"

namespace fisheye_mapping {

class DepthNodelet : public nodelet::Nodelet {
 public:
  ~DepthNodelet() override {
    if (worker_) worker_->stop();
    // The corrections are not lost with the process.
    std::lock_guard<std::mutex> lock(mutex_);
    if (stage_ && stage_->selfCalibration() && stage_->selfCalibration()->changed() && !opts_.self_calibration_file.empty()) {
      try {
        NODELET_INFO("on shutdown: %s", saveSelfCalibration(*stage_, opts_.self_calibration_file, save_folder_).c_str());
      } catch (const std::exception& e) {
        NODELET_ERROR("self-calibration not saved on shutdown: %s", e.what());
      }
    }
  }

 private:
  // cfg/DepthReconfigure.cfg's level bit of the parameters that rebuild the sweep.
  static constexpr uint32_t kSweepLevel = 1;

  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    log_ = NodeletLogger(getName());
    calibration_pub_ = nh.advertise<RigSelfCalibration>("depth/self_calibration", 1, true);
    try {
      // The depth stage's parameters are declared once, in the core
      // (DepthStageConfig, PlaneSweepConfig): the offline FrameSetMapper reads
      // the same names into the same stage object; the node's own in
      // DepthNodeOptions.
      requireKnownParams(pnh, {DepthStageConfig::params().names(), DepthNodeOptions::params().names()});
      config_ = DepthStageConfig::fromParams(RosParams(pnh));
      opts_ = DepthNodeOptions::params().read(RosParams(pnh), DepthNodeOptions());
      save_folder_ = tsdf_node::saveFolder(opts_.save);
      if (save_folder_.allow_any_path) {
        NODELET_WARN("~allow_any_save_path is set (UNSAFE): save_calibration may write any file this node can write");
      }
      monitor_ = std::make_unique<StageMonitor>(nh, pnh, "depth");
      // tf: the rig from camera_infos, and the poses for the self-calibration's translations.
      if (opts_.rig.fromCameraInfo() || (config_.self_calibration.enabled && config_.self_calibration.translation)) {
        tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
        tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
      }
      if (!opts_.rig.fromCameraInfo()) {
        setStage(std::make_unique<DepthStage>(loadRigFromParams(pnh), config_));
      } else {
        NODELET_INFO("plane sweep: rig from the frame sets' camera_infos and tf (base frame %s), reference %s",
                     opts_.base_frame.c_str(), config_.reference_camera.c_str());
      }
    } catch (const std::exception& e) {
      NODELET_FATAL("plane sweep depth not started: %s", e.what());
      return;
    }
    // Each frame set is swept on its own: a reset is logged and counted, no state to clear.
    time_ = std::make_unique<StageTimeline>(*monitor_, log_, "plane sweep", std::vector<std::string>{""},
                                            opts_.time_reset.time_reset_threshold);
    monitor_->setExtraReport([this](diagnostic_updater::DiagnosticStatusWrapper& stat) { report(stat); });
    clock_timer_ = simClockTimer(nh, [this](std::int64_t now) {
      std::lock_guard<std::mutex> lock(time_mutex_);
      time_->clock(now);
    });
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<DepthReconfigureConfig>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](DepthReconfigureConfig& c, uint32_t level) { onReconfigure(c, level); });
    save_service_ = pnh.advertiseService("save_calibration", &DepthNodelet::saveCalibration, this);
    worker_ = std::make_unique<LatestWorker<CameraFrameSetConstPtr>>(
        [this](CameraFrameSetConstPtr& set) { work(set); }, opts_.input_queue);
    advertise(nh);
  }

  // The stage in use (mutex_ held, or before the worker starts), with what
  // depends on its rig: the z-depth rays, the names the diagnostics show.
  void setStage(std::unique_ptr<DepthStage> stage) {
    stage_ = std::move(stage);
    // Built once per rig: per pixel, the z of the reference camera's ray.
    zdepth_ = std::make_unique<ZDepthConverter>(stage_->rig().cameras[stage_->reference()].model);
    {
      std::lock_guard<std::mutex> lock(views_mutex_);
      backend_ = stage_->backendName();
      reference_name_ = stage_->rig().cameras[stage_->reference()].name;
    }
    NODELET_INFO("plane sweep on %s, reference %s, %zu supporting camera(s), %s, self-calibration %s",
                 stage_->backendName().c_str(), reference_name_.c_str(), stage_->supports().size(),
                 toString(config_.sweep.resolution).c_str(), stage_->selfCalibration() ? "on" : "off");
    if (const OnlineRigCalibrator* cal = stage_->selfCalibration()) {
      if (!cal->startError().empty()) {
        NODELET_ERROR("%s", cal->startError().c_str());
        monitor_->error(cal->startError());
      } else if (!cal->config().start_file.empty()) {
        NODELET_INFO("self-calibration started from %s", cal->config().start_file.c_str());
      }
      noteCalibration(std_msgs::Header());
    }
  }

  // The self-calibration's state for the diagnostics and the topic (mutex_ held).
  void noteCalibration(const std_msgs::Header& header) {
    RigSelfCalibration msg = toRigSelfCalibrationMsg(*stage_->selfCalibration(),
                                                     stage_->rig().cameras[stage_->reference()].name, header);
    for (const CameraSelfCalibration& c : msg.cameras) {
      if (c.level != diagnostic_msgs::DiagnosticStatus::OK && !c.reference)
        NODELET_WARN_THROTTLE(10.0, "self-calibration: %s: %s", c.camera.c_str(), c.status.c_str());
    }
    calibration_pub_.publish(msg);
    std::lock_guard<std::mutex> lock(views_mutex_);
    calibration_ = msg;
  }

  bool saveCalibration(FilePath::Request& req, FilePath::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    const std::string requested = req.path.empty() ? opts_.self_calibration_file : req.path;
    try {
      if (!stage_) throw std::runtime_error("the depth stage has no rig yet");
      res.message = saveSelfCalibration(*stage_, requested, save_folder_);
      res.success = true;
      NODELET_INFO("%s", res.message.c_str());
    } catch (const std::exception& e) {
      res.success = false;
      res.message = "save_calibration '" + requested + "' failed: " + e.what();
      monitor_->error(res.message);
      NODELET_ERROR("%s", res.message.c_str());
    }
    return true;
  }

  // ~rig_source camera_info (mutex_ held): whether a stage for this set's
  // CameraInfos exists, building it on the first set and when they change.
  // A set that cannot have one is dropped ("no rig yet"), logged with why.
  bool rigFor(const CameraFrameSet& set) {
    if (!opts_.rig.fromCameraInfo() || (stage_ && rig_key_.describes(set.camera_names, set.camera_infos))) return true;
    // A set without the reference camera is bad input, not a new rig.
    if (std::find(set.camera_names.begin(), set.camera_names.end(), config_.reference_camera) == set.camera_names.end()) {
      throw std::invalid_argument("frame set has no camera named '" + config_.reference_camera +
                                  "' (~reference_camera) among its camera_names");
    }
    stage_.reset();  // the old rig does not describe these images
    std::string why;
    try {
      if (set.camera_infos.size() != set.camera_names.size()) {
        throw std::invalid_argument("frame set has " + std::to_string(set.camera_names.size()) + " camera_names but " +
                                    std::to_string(set.camera_infos.size()) + " camera_infos");
      }
      setStage(std::make_unique<DepthStage>(
          rigFromCameraInfosAndTf(set.camera_infos, set.camera_names, *tf_buffer_, opts_.base_frame, ros::Time(0), 0.2),
          config_));
      rig_key_ = {set.camera_names, set.camera_infos};
      return true;
    } catch (const tf2::TransformException& e) {
      monitor_->tfFailure(why = e.what());
    } catch (const std::exception& e) {
      monitor_->error(std::string("rig from camera_info: ") + (why = e.what()));
    }
    monitor_->dropped("no rig yet");
    NODELET_WARN_THROTTLE(5.0, "frame set at %.3f dropped: no rig yet from its camera_infos and tf: %s",
                          set.header.stamp.toSec(), why.c_str());
    return false;
  }

  void advertise(ros::NodeHandle& nh) {
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    input_ = std::make_unique<LazySubscription>(
        *monitor_, log_, "the frame sets",
        [this] {
          return depth_pub_.getNumSubscribers() > 0 || z_pub_.getNumSubscribers() > 0 ||
                 cost_pub_.getNumSubscribers() > 0 ||
                 (opts_.publish_uniqueness && uniqueness_pub_.getNumSubscribers() > 0);
        },
        [this] { sub_ = getNodeHandle().subscribe("frames", 2, &DepthNodelet::onFrames, this); },
        [this] { sub_.shutdown(); });
    const auto connect = input_->imageCallback();
    depth_pub_ = it_->advertiseCamera("depth/image", 2, connect, connect, input_->rosCallback(), input_->rosCallback());
    z_pub_ = it_->advertise("depth/image_z", 2, connect, connect);
    cost_pub_ = it_->advertise("depth/cost", 2, connect, connect);
    if (opts_.publish_uniqueness) uniqueness_pub_ = it_->advertise("depth/uniqueness", 2, connect, connect);
    // A subscriber that connected while the publishers above were being
    // assigned may have run the connect callback too early (it saw none):
    // look once more now that all of them exist.
    input_->update();
  }

  // The run-time parameters of PlaneSweepConfig::params() (cfg/DepthReconfigure.cfg
  // is checked against them by test_param_declarations), each against its
  // declaration: a value outside its range is refused, the running values stay
  // and are reported back. Filters change in place; the planes and view
  // thresholds (level kSweepLevel) rebuild the sweep, except on the first call:
  // its values are the start-up parameters the stage was built from.
  void onReconfigure(DepthReconfigureConfig& c, uint32_t level) {
    std::lock_guard<std::mutex> lock(mutex_);
    // Over the running sweep: what the .cfg does not hold (min_noise_std, planes, windows) stays.
    const PlaneSweepConfig running = stage_ ? stage_->sweepConfig() : config_.sweep;
    const auto next = checkedReconfigure(c, PlaneSweepConfig::params(), running, *monitor_, log_, "sweep parameters");
    if (!next) return;
    if ((level & kSweepLevel) && reconfigured_) {
      if (stage_) stage_->setSweepConfig(*next);
      config_.sweep = *next;  // also for a stage built later (~rig_source camera_info)
      NODELET_INFO("sweep rebuilt: near %.2f, far %.1f m, ground %.2f + [%.2f, %.2f] m, walls [%.1f, %.1f] m, "
                   "min parallax %.3f px",
                   next->near, next->far, next->ground_height, next->ground_min, next->ground_max, next->wall_min,
                   next->wall_max, next->min_parallax_px);
    } else {
      if (stage_) stage_->setFilters(next->filters);
      config_.sweep.filters = next->filters;
    }
    reconfigured_ = true;
  }

  void report(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    std::lock_guard<std::mutex> lock(views_mutex_);
    stat.add("rig source", opts_.rig.rig_source);
    stat.add("backend", backend_.empty() ? "none yet (no rig)" : backend_);
    stat.add("reference camera", reference_name_.empty() ? config_.reference_camera : reference_name_);
    stat.add("supporting views used", used_views_);
    addSelfCalibrationReport(stat, calibration_, config_.self_calibration.enabled);
  }

  // The subscription's callback: into the worker's mailbox, replacing a set
  // that still waits (the sweep is slower than the frames: the newest set wins).
  void onFrames(const CameraFrameSetConstPtr& set) {
    monitor_->input();
    {
      std::lock_guard<std::mutex> tl(time_mutex_);
      time_->observe(0, set->header.stamp);
    }
    if (worker_->offer(set)) monitor_->dropped("busy");
  }

  void work(const CameraFrameSetConstPtr& set) {
    std::lock_guard<std::mutex> lock(mutex_);
    const double t0 = StageStats::now();
    bool published = false;
    if (!guarded(*monitor_, log_, "frame set", set->header.stamp, [&] { published = process(set); }, 0.2))
      monitor_->dropped("bad input");
    if (published) monitor_->output();
    monitor_->processed(StageStats::now() - t0);
  }

  // The vehicle's pose at `stamp` for the self-calibration's translations,
  // when it corrects them and tf has it now (never waits: the sweep goes
  // on, and that set brings no translation evidence, said once in a while).
  std::optional<Eigen::Isometry3d> vehiclePose(const ros::Time& stamp) {
    if (!tf_buffer_ || !stage_->selfCalibration() || !config_.self_calibration.translation) return std::nullopt;
    std::string why;
    try {
      if (tf_buffer_->canTransform(opts_.world_frame, opts_.base_frame, stamp, &why))
        return toIsometry(tf_buffer_->lookupTransform(opts_.world_frame, opts_.base_frame, stamp));
    } catch (const tf2::TransformException& e) {
      why = e.what();
    }
    NODELET_WARN_THROTTLE(30.0, "self-calibration: no pose of %s in %s at %.3f (%s): translations not updated "
                          "from this frame set", opts_.base_frame.c_str(), opts_.world_frame.c_str(), stamp.toSec(),
                          why.c_str());
    return std::nullopt;
  }

  // False: dropped for want of a rig (counted there).
  bool process(const CameraFrameSetConstPtr& set) {
    if (!rigFor(*set)) return false;
    faultPoint("depth frame set");  // tests only: an exception in the sweep (test_fault_injection_node)
    const Rig& rig = stage_->rig();
    const int ref = stage_->reference();
    sensor_msgs::ImageConstPtr ref_img;
    const std::vector<cv::Mat> images = depthStageImages(set, *stage_, &ref_img);  // empty: not in the set
    const std::optional<Eigen::Isometry3d> pose = vehiclePose(ref_img->header.stamp);
    const DepthResult r = stage_->compute(images, pose ? &*pose : nullptr);
    if (r.calibration_ms > 0) noteCalibration(ref_img->header);
    if (!r.dropped_views.empty()) NODELET_INFO_ONCE("supporting view dropped: %s", r.dropped_views.front().c_str());
    for (const auto& w : r.warnings) NODELET_WARN_THROTTLE(10.0, "frame %.3f: %s", ref_img->header.stamp.toSec(), w.c_str());
    {
      std::lock_guard<std::mutex> lock(views_mutex_);
      used_views_.clear();
      for (const auto& v : r.used_views) used_views_ += (used_views_.empty() ? "" : " ") + v;
    }
    std_msgs::Header header = ref_img->header;
    if (header.frame_id.empty()) header.frame_id = rig.cameras[ref].frame_id;
    sensor_msgs::CameraInfo info = toCameraInfo(rig.cameras[ref], header.stamp);
    info.header = header;
    depth_pub_.publish(*toDepthMsg(header, r.depth), info);
    if (z_pub_.getNumSubscribers() > 0) z_pub_.publish(toDepthMsg(header, zdepth_->convert(r.depth)));
    cost_pub_.publish(toImageMsg(header, r.cost));  // 32FC1
    if (opts_.publish_uniqueness) uniqueness_pub_.publish(toImageMsg(header, r.uniqueness));
    NODELET_DEBUG("depth in %.1f ms (sweep %.1f, filters %.1f)", r.total_ms, r.sweep_ms, r.filter_ms);
    return true;
  }

  DepthStageConfig config_;  // the start-up parameters, with the sweep as reconfigured (mutex_)
  DepthNodeOptions opts_;
  NodeletLogger log_;
  std::unique_ptr<DepthStage> stage_;  // camera_info source: null until the first frame set's rig
  CameraInfoRigKey rig_key_;           // camera_info source: the stage's rig was built from these
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<ZDepthConverter> zdepth_;
  bool reconfigured_ = false;
  SaveFolder save_folder_;  // where save_calibration may write (~save_directory)
  ros::Publisher calibration_pub_;
  ros::ServiceServer save_service_;
  RigSelfCalibration calibration_;  // views_mutex_: the last state, for the diagnostics
  std::mutex mutex_;                // the stage (worker, reconfigure)
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<DepthReconfigureConfig>> reconfigure_;
  ros::Subscriber sub_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::CameraPublisher depth_pub_;
  image_transport::Publisher z_pub_, cost_pub_, uniqueness_pub_;
  std::unique_ptr<StageMonitor> monitor_;
  std::unique_ptr<LazySubscription> input_;
  std::mutex time_mutex_;
  std::unique_ptr<StageTimeline> time_;  // time_mutex_
  ros::WallTimer clock_timer_;
  std::mutex views_mutex_;
  std::string used_views_, backend_, reference_name_;  // views_mutex_
  // The newest frame set not yet swept, and the thread that sweeps it.
  std::unique_ptr<LatestWorker<CameraFrameSetConstPtr>> worker_;  // last: stopped in the destructor first
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::DepthNodelet, nodelet::Nodelet)
