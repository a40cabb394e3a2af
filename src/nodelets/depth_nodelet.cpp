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
//             depth/self_calibration (fisheye_mapping/RigSelfCalibration,
//                               latched: each supporting camera's rotation
//                               correction, residual and state, after each
//                               update of the online self-calibration)
// Services    ~save_calibration (FilePath: the self-calibrated camchain and its
//             mount, the old files kept as .1; empty path: ~self_calibration_file;
//             relative: inside ~save_directory, $ROS_HOME/fisheye_mapping by
//             default; outside it refused unless ~allow_any_save_path, unsafe;
//             links replaced, never followed; FIFOs and devices refused;
//             every write verified). The same save runs on shutdown when a
//             correction was applied.
// Parameters  ~rig_source (camchain | camera_info; default camchain),
//             ~camchain, ~mount (camchain source), ~base_frame (camera_info
//             source, default base_link): the rig from the frame sets'
//             camera_infos and each camera frame's pose in it from tf2, built
//             on the first frame set and again only when the CameraInfos
//             change; until then sets are dropped ("no rig yet"),
//             ~reference_camera (cam0; a name of the sets' camera_names),
//             ~support_cameras (list; default all others), ~self_masks
//             (dict camera -> mask image path, non-zero = car body),
//             plane-sweep parameters (see config/plane_sweep_depth.yaml);
//             filter thresholds and near / far / ground_height / ground_min /
//             ground_max / wall_min / wall_max / min_parallax_* / min_overlap also through
//             dynamic_reconfigure (cfg/DepthReconfigure.cfg; the latter
//             rebuild the sweep), ~time_reset_threshold (s, default 1; 0: never),
//             ~self_calibration* (the online rotation self-calibration, on by
//             default: core/camera/online_calibration.h), ~self_calibration_file.
//             /diagnostics (StageMonitor "depth"): input / output rates,
//             processing time, drops by reason ("busy", "bad input" - logged
//             with the stamp, the stage goes on), time resets, backend,
//             supporting views used, each camera's self-calibration (WARN
//             naming a camera that gets no update, and why).
// Time going backwards (frame-set stamps back by more than the threshold, or
// the sim clock behind the newest stamp) is logged with both stamps and
// counted; the stage keeps no other state keyed on time (each frame set is
// swept on its own, the mailbox holds one set).
#include <algorithm>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <mutex>
#include <thread>

#include <diagnostic_msgs/DiagnosticStatus.h>
#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <sensor_msgs/Image.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/FilePath.h"
#include "fisheye_mapping/RigSelfCalibration.h"
#include "fisheye_mapping/DepthReconfigureConfig.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/depth/depth_stage.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"
#include "fisheye_mapping/core/common/stream_timeline.h"
#include "fisheye_mapping/ros/camera_info.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/node_options.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_monitor.h"
#include "fisheye_mapping/ros/tsdf_node_helpers.h"

namespace fisheye_mapping {

class DepthNodelet : public nodelet::Nodelet {
 public:
  ~DepthNodelet() override {
    {
      std::lock_guard<std::mutex> lock(mailbox_mutex_);
      stopping_ = true;
    }
    mailbox_cv_.notify_all();
    if (worker_.joinable()) worker_.join();
    // The corrections are not lost with the process.
    std::lock_guard<std::mutex> lock(mutex_);
    if (stage_ && stage_->selfCalibration() && stage_->selfCalibration()->changed() && !calibration_file_.empty()) {
      try {
        const std::string path = confineSavePath(calibration_file_, save_folder_);
        stage_->saveCalibration(path);
        NODELET_INFO("self-calibration saved on shutdown to %s", path.c_str());
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
    double time_reset = 1.0;
    calibration_pub_ = nh.advertise<RigSelfCalibration>("depth/self_calibration", 1, true);
    try {
      // The depth stage's parameters are declared once, in the core
      // (DepthStageConfig, PlaneSweepConfig): the offline FrameSetMapper reads
      // the same names into the same stage object; the node's own in
      // DepthNodeOptions.
      requireKnownParams(pnh, {DepthStageConfig::params().names(), DepthNodeOptions::params().names()});
      config_ = DepthStageConfig::fromParams(RosParams(pnh));
      const DepthNodeOptions opts = DepthNodeOptions::params().read(RosParams(pnh), DepthNodeOptions());
      rig_source_ = opts.rig.rig_source;
      base_frame_ = opts.base_frame;
      publish_uniqueness_ = opts.publish_uniqueness;
      calibration_file_ = opts.self_calibration_file;
      save_folder_ = tsdf_node::saveFolder(opts.save);
      if (save_folder_.allow_any_path) {
        NODELET_WARN("~allow_any_save_path is set (UNSAFE): save_calibration may write any file this node can write");
      }
      time_reset = opts.time_reset.time_reset_threshold;
      monitor_ = std::make_unique<StageMonitor>(nh, pnh, "depth");
      if (!opts.rig.fromCameraInfo()) {
        setStage(std::make_unique<DepthStage>(loadRigFromParams(pnh), config_));
      } else {
        tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
        tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
        NODELET_INFO("plane sweep: rig from the frame sets' camera_infos and tf (base frame %s), reference %s",
                     base_frame_.c_str(), config_.reference_camera.c_str());
      }
    } catch (const std::exception& e) {
      NODELET_FATAL("plane sweep depth not started: %s", e.what());
      return;
    }
    timeline_ = std::make_unique<StreamTimeline>(1, time_reset);
    monitor_->setExtraReport([this](diagnostic_updater::DiagnosticStatusWrapper& stat) { report(stat); });
    clock_timer_ = nh.createWallTimer(ros::WallDuration(0.2), [this](const ros::WallTimerEvent&) { checkClock(); });
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<DepthReconfigureConfig>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](DepthReconfigureConfig& c, uint32_t level) { onReconfigure(c, level); });
    save_service_ = pnh.advertiseService("save_calibration", &DepthNodelet::saveCalibration, this);
    worker_ = std::thread([this] { work(); });
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
    const OnlineRigCalibrator* cal = stage_->selfCalibration();
    RigSelfCalibration msg;
    msg.header = header;
    msg.reference_camera = stage_->rig().cameras[stage_->reference()].name;
    msg.frame_sets = cal->frameSets();
    msg.updates = cal->updates();
    msg.last_update_ms = cal->lastUpdateMs();
    msg.note = cal->lastNote();
    msg.start_error = cal->startError();
    for (const CameraCalibrationState& c : cal->state()) {
      CameraSelfCalibration m;
      m.camera = c.name;
      m.reference = c.reference;
      m.level = c.warn ? diagnostic_msgs::DiagnosticStatus::WARN : diagnostic_msgs::DiagnosticStatus::OK;
      m.status = c.status;
      for (int a = 0; a < 3; ++a) m.correction_rotvec_deg[a] = c.correction_rotvec_deg[a];
      m.correction_deg = c.correction_deg;
      m.residual_deg = c.residual_deg;
      m.inliers = c.inliers;
      m.updates = c.updates;
      m.refused = c.refused;
      m.restarts = c.restarts;
      if (c.warn && !c.reference) NODELET_WARN_THROTTLE(10.0, "self-calibration: %s: %s", c.name.c_str(), c.status.c_str());
      msg.cameras.push_back(m);
    }
    calibration_pub_.publish(msg);
    std::lock_guard<std::mutex> lock(views_mutex_);
    calibration_ = msg;
  }

  bool saveCalibration(FilePath::Request& req, FilePath::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    const std::string requested = req.path.empty() ? calibration_file_ : req.path;
    try {
      if (!stage_) throw std::runtime_error("the depth stage has no rig yet");
      if (requested.empty()) throw std::invalid_argument("no path given and ~self_calibration_file is empty");
      // Inside ~save_directory (confineSavePath creates missing folders).
      const std::string path = confineSavePath(requested, save_folder_);
      stage_->saveCalibration(path);
      res.success = true;
      res.message = "self-calibrated camchain saved to " + path + " (mount: " +
                    OnlineRigCalibrator::savedMountPath(path) + ")";
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
    if (rig_source_ != "camera_info") return true;
    if (stage_ && set.camera_names == rig_names_ && set.camera_infos.size() == rig_infos_.size() &&
        std::equal(rig_infos_.begin(), rig_infos_.end(), set.camera_infos.begin(), sameCalibration)) {
      return true;
    }
    // A set without the reference camera is bad input, not a new rig.
    if (std::find(set.camera_names.begin(), set.camera_names.end(), config_.reference_camera) == set.camera_names.end()) {
      throw std::invalid_argument("frame set has no camera named '" + config_.reference_camera +
                                  "' (~reference_camera) among its camera_names");
    }
    stage_.reset();  // the old rig does not describe these images
    try {
      if (set.camera_infos.size() != set.camera_names.size()) {
        throw std::invalid_argument("frame set has " + std::to_string(set.camera_names.size()) + " camera_names but " +
                                    std::to_string(set.camera_infos.size()) + " camera_infos");
      }
      setStage(std::make_unique<DepthStage>(
          rigFromCameraInfosAndTf(set.camera_infos, set.camera_names, *tf_buffer_, base_frame_, ros::Time(0), 0.2),
          config_));
      rig_infos_ = set.camera_infos;
      rig_names_ = set.camera_names;
      return true;
    } catch (const tf2::TransformException& e) {
      monitor_->tfFailure(e.what());
      noRig(set, e.what());
    } catch (const std::exception& e) {
      monitor_->error(std::string("rig from camera_info: ") + e.what());
      noRig(set, e.what());
    }
    return false;
  }

  void noRig(const CameraFrameSet& set, const std::string& why) {
    monitor_->dropped("no rig yet");
    NODELET_WARN_THROTTLE(5.0, "frame set at %.3f dropped: no rig yet from its camera_infos and tf: %s",
                          set.header.stamp.toSec(), why.c_str());
  }

  void advertise(ros::NodeHandle& nh) {
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    auto connect = [this](const image_transport::SingleSubscriberPublisher&) { updateSubscription(); };
    auto info_connect = [this](const ros::SingleSubscriberPublisher&) { updateSubscription(); };
    depth_pub_ = it_->advertiseCamera("depth/image", 2, connect, connect, info_connect, info_connect);
    z_pub_ = it_->advertise("depth/image_z", 2, connect, connect);
    cost_pub_ = it_->advertise("depth/cost", 2, connect, connect);
    if (publish_uniqueness_) uniqueness_pub_ = it_->advertise("depth/uniqueness", 2, connect, connect);
    // A subscriber that connected while the publishers above were being
    // assigned may have run the connect callback too early (it saw none):
    // look once more now that all of them exist.
    updateSubscription();
  }

  // The run-time parameters of PlaneSweepConfig::params() (cfg/DepthReconfigure.cfg
  // is checked against them by test_param_declarations), each against its
  // declaration: a value outside its range is refused, the running values stay
  // and are reported back. Filters change in place; the planes and view
  // thresholds (level kSweepLevel) rebuild the sweep, except on the first call:
  // its values are the start-up parameters the stage was built from.
  void onReconfigure(DepthReconfigureConfig& c, uint32_t level) {
    dynamic_reconfigure::Config values;
    c.__toMessage__(values);
    std::lock_guard<std::mutex> lock(mutex_);
    // Over the running sweep: what the .cfg does not hold (min_noise_std, planes, windows) stays.
    const PlaneSweepConfig running = stage_ ? stage_->sweepConfig() : config_.sweep;
    std::string error;
    const std::optional<PlaneSweepConfig> next = reconfigured(PlaneSweepConfig::params(), running, values, error);
    if (!next) {
      keepRunningValues(c, std::make_pair(std::cref(PlaneSweepConfig::params()), running));
      monitor_->error("sweep parameters refused: " + error);
      NODELET_ERROR("sweep parameters refused, running values kept: %s", error.c_str());
      return;
    }
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

  void updateSubscription() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    const bool wanted = depth_pub_.getNumSubscribers() > 0 || z_pub_.getNumSubscribers() > 0 ||
                        cost_pub_.getNumSubscribers() > 0 ||
                        (publish_uniqueness_ && uniqueness_pub_.getNumSubscribers() > 0);
    try {
      if (wanted && !sub_) {
        sub_ = getNodeHandle().subscribe("frames", 2, &DepthNodelet::onFrames, this);
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
    std::lock_guard<std::mutex> lock(views_mutex_);
    stat.add("rig source", rig_source_);
    stat.add("backend", backend_.empty() ? "none yet (no rig)" : backend_);
    stat.add("reference camera", reference_name_.empty() ? config_.reference_camera : reference_name_);
    stat.add("supporting views used", used_views_);
    if (calibration_.cameras.empty()) {
      stat.add("self-calibration", config_.self_calibration.enabled ? "on, no rig yet" : "off");
      return;
    }
    stat.add("self-calibration", std::to_string(calibration_.updates) + " updates over " +
                                     std::to_string(calibration_.frame_sets) + " frame sets, last " +
                                     formatMs(calibration_.last_update_ms) +
                                     (calibration_.note.empty() ? "" : "; " + calibration_.note));
    if (!calibration_.start_error.empty()) stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, calibration_.start_error);
    for (const CameraSelfCalibration& c : calibration_.cameras) {
      if (c.reference) continue;
      char line[160];
      std::snprintf(line, sizeof(line), "correction %.3f deg, residual %.3f deg, %d inliers, %d updates: ",
                    c.correction_deg, c.residual_deg, c.inliers, c.updates);
      stat.add("self-calibration " + c.camera, line + c.status);
      if (c.level != diagnostic_msgs::DiagnosticStatus::OK)
        stat.mergeSummary(c.level, "self-calibration " + c.camera + ": " + c.status);
    }
  }

  static std::string formatMs(double ms) {
    char b[32];
    std::snprintf(b, sizeof(b), "%.0f ms", ms);
    return b;
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
        if (process(*set, set)) monitor_->output();
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

  // False: dropped for want of a rig (counted there).
  bool process(const CameraFrameSet& set, const CameraFrameSetConstPtr& owner) {
    if (set.camera_names.size() != set.images.size()) {
      throw std::invalid_argument("frame set has " + std::to_string(set.camera_names.size()) + " names but " +
                                  std::to_string(set.images.size()) + " images");
    }
    if (!rigFor(set)) return false;
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
    if (r.calibration_ms > 0) {
      std_msgs::Header h = ref_img->header;
      noteCalibration(h);
    }
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
    return true;
  }

  void publish(const std_msgs::Header& header, const DepthResult& r) {
    sensor_msgs::CameraInfo info = toCameraInfo(stage_->rig().cameras[stage_->reference()], header.stamp);
    info.header = header;
    depth_pub_.publish(*toDepthMsg(header, r.depth), info);
    if (z_pub_.getNumSubscribers() > 0) z_pub_.publish(toDepthMsg(header, zdepth_->convert(r.depth)));
    cost_pub_.publish(toImageMsg(header, r.cost));  // 32FC1
    if (publish_uniqueness_) uniqueness_pub_.publish(toImageMsg(header, r.uniqueness));
  }

  DepthStageConfig config_;  // the start-up parameters, with the sweep as reconfigured (mutex_)
  std::string rig_source_ = "camchain", base_frame_;
  std::unique_ptr<DepthStage> stage_;  // camera_info source: null until the first frame set's rig
  std::vector<sensor_msgs::CameraInfo> rig_infos_;  // camera_info source: the stage's rig was built from these
  std::vector<std::string> rig_names_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<ZDepthConverter> zdepth_;
  bool publish_uniqueness_ = false, reconfigured_ = false;
  std::string calibration_file_;
  SaveFolder save_folder_;  // where save_calibration may write (~save_directory)
  ros::Publisher calibration_pub_;
  ros::ServiceServer save_service_;
  RigSelfCalibration calibration_;  // views_mutex_: the last state, for the diagnostics
  std::mutex mutex_, connect_mutex_;  // mutex_: the stage (worker, reconfigure)
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<DepthReconfigureConfig>> reconfigure_;
  ros::Subscriber sub_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::CameraPublisher depth_pub_;
  image_transport::Publisher z_pub_, cost_pub_, uniqueness_pub_;
  std::mutex time_mutex_;
  std::unique_ptr<StreamTimeline> timeline_;
  std::unique_ptr<StageMonitor> monitor_;
  ros::WallTimer clock_timer_;
  std::mutex views_mutex_;
  std::string used_views_, backend_, reference_name_;  // views_mutex_
  // The mailbox: the newest frame set not yet swept.
  std::mutex mailbox_mutex_;
  std::condition_variable mailbox_cv_;
  CameraFrameSetConstPtr mailbox_;
  bool stopping_ = false;
  std::thread worker_;  // last: joined in the destructor before the rest goes
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::DepthNodelet, nodelet::Nodelet)
