// TSDF fusion nodelet: the core TsdfFusionStage (map, mesh, map file, time
// resets, intensity, carving, obstacle grid) between its topics.
//
// Topics are relative to the node's namespace (vehicle.launch: /fisheye_mapping).
// Subscribes  depth_masked/image (32FC1 range along the ray, NaN invalid), through a
//             tf2 MessageFilter (a frame waits for its pose); with ~rig_source
//             camera_info, depth_masked/camera_info gives each frame's camera model
//             (frames before their first CameraInfo wait for it: the last 8,
//             2 s at most, ImagesWithModels; others are dropped, "no camera_info yet");
//             image (the reference camera, for the map's intensity; ~intensity);
//             depth_masked/vehicles (carve regions of parked vehicles that drove off);
//             depth_masked/held (32FC1: depth of vehicles decided parked, held back
//             while undecided, stamped with an earlier fused frame: fused with
//             that frame's pose, TsdfFusionStage::fuseHeld).
// Publishes   tsdf/mesh (MarkerArray, changed blocks; a late subscriber gets all),
//             tsdf/cloud (PointCloud2 x y z intensity), tsdf/occupancy (latched
//             OccupancyGrid every ~occupancy_period s), tsdf/fusion_done (one
//             FrameDone per depth frame, for the paced player), /diagnostics ("tsdf").
// Services    ~save_mesh, ~save_cloud, ~save_map, ~load_map (FilePath, confined to
//             ~save_directory: core/common/safe_write.h), ~clear_map (Trigger).
// Parameters  docs/parameters.md (TsdfConfig, TsdfNodeOptions); max_range,
//             min_observations, publish_period also at run time (cfg/TsdfReconfigure.cfg).
// Nothing the user built is lost: exceptions in callbacks are caught, logged
// with the frame stamp and counted; SIGTERM saves like SIGINT; the map file's
// policy (backup, reload, autosave) is the core's MapSession.
#include <atomic>
#include <memory>
#include <mutex>

#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include "fisheye_mapping/TsdfReconfigureConfig.h"
#include "fisheye_mapping/core/tsdf/fusion_stage.h"
#include "fisheye_mapping/ros/camera_models.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/file_services.h"
#include "fisheye_mapping/ros/node_options.h"
#include "fisheye_mapping/ros/nodelet_glue.h"
#include "fisheye_mapping/ros/posed_input.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_monitor.h"
#include "fisheye_mapping/ros/tsdf_messages.h"
#include "fisheye_mapping/ros/tsdf_topics.h"
#include "fisheye_mapping/ros/tsdf_node_helpers.h"

namespace fisheye_mapping {

class TsdfNodelet : public nodelet::Nodelet {
 public:
  ~TsdfNodelet() override {
    for (ros::WallTimer* t : {&autosave_timer_, &timer_, &occupancy_timer_, &hold_timer_}) t->stop();
    std::lock_guard<std::mutex> lock(mutex_);
    if (stage_) stage_->shutdown();
    if (sigterm_acquired_) tsdf_node::releaseSigterm();
  }

 private:
  using ImagePtr = sensor_msgs::ImageConstPtr;

  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    log_ = NodeletLogger(getName());
    TsdfConfig cfg;
    try {  // every parameter declared once: the map's in TsdfConfig, the node's in TsdfNodeOptions
      requireKnownParams(pnh, {TsdfConfig::params().names(), TsdfNodeOptions::params().names(), {"output_directory"}});
      opts_ = TsdfNodeOptions::params().read(RosParams(pnh), TsdfNodeOptions());
      save_folder_ = tsdf_node::saveFolder(opts_.save);
      if (pnh.hasParam("output_directory")) {
        NODELET_WARN("~output_directory is no longer read: relative service paths resolve inside ~save_directory (%s)",
                     save_folder_.directory.c_str());
      }
      if (save_folder_.allow_any_path) {
        NODELET_WARN("~allow_any_save_path is set (UNSAFE): save requests may write any file this node can write");
      }
      cfg = TsdfConfig::fromParams(RosParams(pnh));
      images_ = std::make_unique<ImagesWithModels>(
          opts_.rig.fromCameraInfo(), opts_.rig.fromCameraInfo() ? Rig() : loadRigFromParams(pnh),
          [this](const ImagePtr& msg, const std::shared_ptr<const CameraModel>& model) { processDepth(msg, model); });
      monitor_ = std::make_unique<StageMonitor>(nh, pnh, "tsdf");
      TsdfStageOptions so{opts_.save_map_on_shutdown.empty() ? std::string()  // inside the save folder, else refused
                                                             : confineSavePath(opts_.save_map_on_shutdown, save_folder_),
                          opts_.reload_map_on_start, opts_.clear_map_on_time_reset,
                          opts_.time_reset.time_reset_threshold, opts_.occupancy};
      stage_ = std::make_unique<TsdfFusionStage>(cfg, so, [this](bool error, const std::string& m) { log_.say(error, m); });
    } catch (const std::exception& e) {
      NODELET_ERROR("TSDF fusion not started: %s", e.what());
      return;
    }
    sigterm_acquired_ = true;
    NODELET_INFO("%s", tsdf_node::acquireSigterm().c_str());

    if (opts_.rig.fromCameraInfo()) {
      info_sub_ = nh.subscribe("depth_masked/camera_info", 10, &TsdfNodelet::onCameraInfo, this);
      // Frames that waited too long are dropped, "no camera_info yet".
      hold_timer_ = nh.createWallTimer(ros::WallDuration(0.25), [this](const ros::WallTimerEvent&) { images_->expire(); });
    }
    vehicles_sub_ = nh.subscribe("depth_masked/vehicles", 5, &TsdfNodelet::onVehicles, this);
    held_sub_ = nh.subscribe("depth_masked/held", 10, &TsdfNodelet::onHeld, this);
    if (opts_.intensity) {
      it_ = std::make_unique<image_transport::ImageTransport>(nh);
      image_sub_ = it_->subscribe("image", 4, &TsdfNodelet::onImage, this);
    }
    depth_in_ = std::make_unique<PosedImageInput>(
        nh, "depth_masked/image", opts_.world_frame, opts_.queue_size, [this](const ImagePtr&) { monitor_->input(); },
        [this](const ImagePtr& msg) { images_->arrive(msg); },
        [this](const ImagePtr& msg, const std::string& drop, const std::string& why) {
          guarded(depth_errors_, "tf failure", [&] { onTfFailure(msg, drop, why); });
        });
    topics_ = std::make_unique<TsdfTopics>(nh, opts_.world_frame, cfg.colour, [this](const ros::SingleSubscriberPublisher& p) {
      guarded(timer_errors_, "mesh subscriber connect", [&] { locked([&] { if (topics_) topics_->sendAll(*stage_, p); }); });
    });
    auto every = [&](double period, const char* what, std::function<void()> fn) {  // fn under mutex_
      return nh.createWallTimer(ros::WallDuration(period), [this, what, fn](const ros::WallTimerEvent&) {
        guarded(timer_errors_, what, [&] {
          locked([&] {
            faultPoint(what);  // tests only (test_fault_injection_node)
            fn();
          });
        });
      });
    };
    if (opts_.occupancy_period > 0) {
      occupancy_timer_ = every(opts_.occupancy_period, "occupancy timer", [this] { topics_->publishOccupancy(*stage_); });
    }
    timer_ = every(opts_.publish_period, "publish timer", [this] { topics_->publish(*stage_); });
    if (opts_.autosave_period > 0.0 && !stage_->persistent()) {
      NODELET_WARN("~autosave_period %.1f s ignored: ~save_map_on_shutdown is not set", opts_.autosave_period);
    } else if (opts_.autosave_period > 0.0) {
      autosave_timer_ = every(opts_.autosave_period, "autosave timer", [this] { stage_->autosave(); });
    }
    advertiseServices(pnh);
    monitor_->setExtraReport([this](diagnostic_updater::DiagnosticStatusWrapper& stat) { diagnose(stat); });
    // After the timer exists: the first callback (the start-up values) may set its period.
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<TsdfReconfigureConfig>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](TsdfReconfigureConfig& c, uint32_t) {
      guarded(service_errors_, "reconfigure", [&] { onReconfigure(c); });
    });
    NODELET_INFO("TSDF fusion: voxel %.3f m, truncation %.3f m, local map %.0fx%.0fx%.0f m, %s integrator",
                 cfg.voxel_size, cfg.truncation(), cfg.local_map_size.x(), cfg.local_map_size.y(),
                 cfg.local_map_size.z(), toString(cfg.integrator));
  }

  // A value outside its declared range is refused: the running values stay
  // and are reported back. Only what applies without a new map is run-time.
  void onReconfigure(TsdfReconfigureConfig& c) {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto next = checkedReconfigure(c, TsdfConfig::params(), stage_->config(), TsdfNodeOptions::params(), opts_,
                                         *monitor_, log_, "reconfigure");
    if (!next) return;
    topics_->markChanged(stage_->reconfigure(next->first));
    if (next->second.publish_period != opts_.publish_period) timer_.setPeriod(ros::WallDuration(next->second.publish_period));
    opts_ = next->second;
    NODELET_INFO("reconfigured: max_range %.2f m (0: none), min_observations %d, publish_period %.2f s",
                 next->first.max_range, next->first.min_observations, opts_.publish_period);
  }

  // Runs fn; an exception is logged with the last frame's stamp and counted
  // by kind, and the stage goes on. Returns the exception's message, or "".
  template <typename Fn>
  std::string guarded(std::atomic<size_t>& counter, const char* where, Fn fn) {
    try {
      fn();
      return "";
    } catch (const std::exception& e) {
      return failed(counter, where, e.what());
    } catch (...) {
      return failed(counter, where, "unknown exception");
    }
  }
  std::string failed(std::atomic<size_t>& counter, const char* where, const std::string& why) {
    ++counter;
    noteCallbackError(*monitor_, log_, where, last_stamp_seen_, why, 5.0);
    return why;
  }

  template <typename Fn>
  void locked(Fn fn) {
    std::lock_guard<std::mutex> lock(mutex_);
    fn();
  }

  // Time went back by more than the threshold (a bag played again): the tf
  // cache is cleared; the stage keeps the map, or clears it on request. mutex_ held.
  bool timeReset(const std::string& reason) {
    monitor_->timeReset("depth frames: " + reason);
    NODELET_WARN("depth frames: %s; tf cache cleared, %s", reason.c_str(),
                 opts_.clear_map_on_time_reset ? "map cleared (~clear_map_on_time_reset)"
                                               : "map kept (~clear_map_on_time_reset: false; call ~clear_map to start afresh)");
    depth_in_->clear();
    topics_->publishReset(*stage_);
    return true;
  }

  // A frame the tf filter gave up on: dropped and acknowledged. A bag played
  // again shows here first (its tf lies before the cache's newest data).
  void onTfFailure(const ImagePtr& msg, const std::string& drop, const std::string& why) {
    monitor_->dropped(drop);
    if (drop == "no pose") monitor_->tfFailure(why);
    log_.throttled(ros::console::levels::Warn, 5.0, "tf failure", "depth frame dropped: " + why);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      std::string reason;
      if (stage_->checkTimeReset(std::int64_t(msg->header.stamp.toNSec()), &reason)) timeReset(reason);
    }
    topics_->frameDone(msg->header, why);
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<std::string> warnings;
    const auto values = stage_->report(&warnings);
    for (const std::string& w : warnings) stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, w);
    stat.add("rig source", opts_.rig.rig_source);
    for (const auto& [name, value] : values) stat.add(name, value);
    stat.add("exceptions in depth callbacks", static_cast<size_t>(depth_errors_));
    stat.add("exceptions in services", static_cast<size_t>(service_errors_));
    stat.add("failed service requests", files_->failures());
    stat.add("exceptions in timers", static_cast<size_t>(timer_errors_));
    stat.add("intensity images unreadable", static_cast<size_t>(image_errors_));
    stat.add("mesh blocks on screen", topics_->numShown());
    stat.add("held depth frames fused / skipped",
             std::to_string(stage_->heldFramesFused()) + " / " + std::to_string(static_cast<size_t>(held_skipped_)));
  }

  // Fuses one frame; every path acknowledges it (tsdf/fusion_done), saying why it was skipped.
  void processDepth(const ImagePtr& msg, const std::shared_ptr<const CameraModel>& model) {
    last_stamp_seen_ = msg->header.stamp;
    std::string skipped;
    const std::string error = guarded(depth_errors_, "depth", [&] { skipped = fuse(msg, model); });
    if (!error.empty()) monitor_->dropped("error"), skipped = "error: " + error;
    guarded(depth_errors_, "fusion_done", [&] { topics_->frameDone(msg->header, skipped); });
  }

  // Empty when fused, else why not (the drop counted by reason, logged).
  std::string fuse(const ImagePtr& msg, const std::shared_ptr<const CameraModel>& model) {
    auto skip = [this](const std::string& reason, const std::string& why) {
      monitor_->dropped(reason);
      NODELET_WARN_THROTTLE(5.0, "depth frame skipped: %s", why.c_str());
      return why;
    };
    const std::string frame = msg->header.frame_id;
    if (!model) {
      const auto [drop, why] = images_->noModel(frame, getNodeHandle().resolveName("depth_masked/camera_info"));
      return skip(drop, why);
    }
    try {
      checkDepthImage(*msg, getNodeHandle().resolveName("depth_masked/image"));
    } catch (const ImageConversionError& e) {
      return skip("bad image", e.what());
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      const TsdfFusionStage::Admission a = stage_->admit(std::int64_t(msg->header.stamp.toNSec()));
      if (a.verdict == TsdfFusionStage::Verdict::kTimeReset && timeReset(a.reason)) {
        monitor_->dropped("time reset");  // its pose came from the tf cache of the old time line
        return "time went backwards: time state reset, frame skipped";
      }
      if (a.verdict == TsdfFusionStage::Verdict::kOutOfOrder) return skip("out of order", a.reason + " (out of order)");
    }
    Eigen::Isometry3d T_W_C, T_W_B;
    try {
      T_W_C = depth_in_->pose(frame, msg->header.stamp);
      T_W_B = depth_in_->pose(opts_.base_frame, msg->header.stamp);
    } catch (const tf2::TransformException& e) {
      monitor_->tfFailure(e.what());
      return skip("no pose", std::string("no pose: ") + e.what());
    }
    cv::Mat depth;
    try {
      depth = toDepthShare(msg);
    } catch (const ImageConversionError& e) {
      return skip("bad image", std::string("unreadable depth image: ") + e.what());
    }
    std::lock_guard<std::mutex> lock(mutex_);
    const double t0 = StageStats::now();
    TsdfFusionStage::Fused f;
    faultPoint("tsdf fusion");  // tests only: an exception in the fusion (test_fault_injection_node)
    try {
      f = stage_->fuse(depth, *model, T_W_C, T_W_B, std::int64_t(msg->header.stamp.toNSec()));
    } catch (const std::invalid_argument& e) {
      return skip("rejected by the map", e.what());
    }
    last_model_ = model;
    last_model_frame_ = frame;
    monitor_->processed(StageStats::now() - t0);
    monitor_->output();  // the stage's product: a frame in the map
    if (!f.intensity_note.empty()) NODELET_WARN_THROTTLE(5.0, "%s", f.intensity_note.c_str());
    return "";
  }

  // Held depth of vehicles decided parked (the depth mask stage's
  // VehicleDepthHold): fused with the pose of the frame of its stamp, fused
  // earlier; skipped (counted) when that frame is not among the last fused.
  void onHeld(const ImagePtr& msg) {
    const std::string error = guarded(depth_errors_, "held depth", [&] {
      checkDepthImage(*msg, getNodeHandle().resolveName("depth_masked/held"));
      const cv::Mat depth = toDepthShare(msg);
      std::lock_guard<std::mutex> lock(mutex_);
      if (!last_model_ || last_model_frame_ != msg->header.frame_id) {
        ++held_skipped_;
        return;
      }
      if (!stage_->fuseHeld(depth, *last_model_, std::int64_t(msg->header.stamp.toNSec()))) ++held_skipped_;
    });
    if (!error.empty()) ++held_skipped_;  // logged and counted by guarded
  }

  // The reference camera's images, for the depth frames of their stamps.
  void onImage(const ImagePtr& msg) {
    try {
      const cv::Mat grey = toCvImageShare(msg, ImageTarget::kGrey8, getNodeHandle().resolveName("image")).clone();
      std::lock_guard<std::mutex> lock(mutex_);
      stage_->addGrey(std::int64_t(msg->header.stamp.toNSec()), grey);
    } catch (const std::exception& e) {
      ++image_errors_;
      NODELET_WARN_THROTTLE(5.0, "intensity image skipped (the map is fused without its grey): %s", e.what());
    }
  }

  // A CameraInfo's model, parsed again only when the calibration changes; a
  // bad one is logged and counted, and that frame's depth dropped until a good one.
  void onCameraInfo(const sensor_msgs::CameraInfoConstPtr& msg) {
    try {
      if (images_->update(*msg)) {
        NODELET_INFO("camera model of frame '%s' from its CameraInfo (%s, %ux%u)", msg->header.frame_id.c_str(),
                     msg->distortion_model.c_str(), msg->width, msg->height);
      }
    } catch (const std::exception& e) {
      monitor_->error(std::string("camera_info: ") + e.what());
      NODELET_ERROR_THROTTLE(5.0, "camera_info rejected: %s", e.what());
    }
  }

  void advertiseServices(ros::NodeHandle& pnh) {
    using A = FilePathServices::Access;
    files_ = std::make_unique<FilePathServices>(pnh, save_folder_, mutex_, [this] { return stage_ != nullptr; },
                                                [this](bool error, const std::string& m) { log_.say(error, m); });
    files_->add("save_mesh", "save mesh to", A::kSave, [this](const std::string& p) { topics_->markChanged(stage_->saveMesh(p)); });
    files_->add("save_cloud", "save cloud to", A::kSave, [this](const std::string& p) { topics_->markChanged(stage_->saveCloud(p)); });
    files_->add("save_map", "save map to", A::kSave, [this](const std::string& p) { stage_->saveMap(p); });
    files_->add("load_map", "load map from", A::kLoad, [this](const std::string& p) { stage_->loadMap(p), topics_->publishReset(*stage_); });
    files_->addTrigger("clear_map", "clear map", [this] { stage_->clear(), topics_->publishReset(*stage_); });
  }

  // The carve regions (parked vehicles that drove off), in the map's frame;
  // another frame is refused once, named in the log.
  void onVehicles(const TrackedVehicleArrayConstPtr& msg) {
    if (msg->world_frame != opts_.world_frame) {
      NODELET_WARN_ONCE("depth_masked/vehicles is in frame '%s', the map in '%s': its carve regions are ignored",
                        msg->world_frame.c_str(), opts_.world_frame.c_str());
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    stage_->setCarve(carveRegions(*msg), std::int64_t(msg->header.stamp.toNSec()));
  }

  std::mutex mutex_;        // the stage, opts_
  std::unique_ptr<TsdfFusionStage> stage_;
  TsdfNodeOptions opts_;    // publish_period as it runs
  SaveFolder save_folder_;  // where saves may write (~save_directory)
  std::unique_ptr<ImagesWithModels> images_;  // depth frames, in order, with their camera models
  std::unique_ptr<PosedImageInput> depth_in_;  // depth frames, each once its pose is in the tf buffer
  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::Subscriber image_sub_;
  ros::Subscriber info_sub_, vehicles_sub_, held_sub_;
  std::shared_ptr<const CameraModel> last_model_;  // mutex_: the last fused frame's camera (held depth)
  std::string last_model_frame_;                   // mutex_
  std::atomic<size_t> held_skipped_{0};
  std::unique_ptr<FilePathServices> files_;
  ros::WallTimer timer_, autosave_timer_, occupancy_timer_, hold_timer_;
  std::unique_ptr<StageMonitor> monitor_;
  std::unique_ptr<TsdfTopics> topics_;  // mesh, cloud, obstacle grid
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<TsdfReconfigureConfig>> reconfigure_;
  NodeletLogger log_;
  bool sigterm_acquired_ = false;
  ros::Time last_stamp_seen_;  // of the last depth frame received (for error logs)
  // Exceptions caught per kind of callback.
  std::atomic<size_t> depth_errors_{0}, service_errors_{0}, timer_errors_{0}, image_errors_{0};
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::TsdfNodelet, nodelet::Nodelet)
