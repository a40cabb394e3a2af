// TSDF fusion nodelet: fuses (masked) fisheye depth into the core TsdfMap.
//
// Topics are relative to the node's namespace (vehicle.launch: /fisheye_mapping).
// Subscribes  depth_masked/image (sensor_msgs/Image 32FC1, range along the ray, NaN invalid)
//             through a tf2 MessageFilter, so a frame waits for its pose.
//             With ~rig_source camera_info: depth_masked/camera_info, the
//             camera model of each depth image (the latest CameraInfo of its
//             frame_id; frames that come before their first CameraInfo wait
//             for it, the last kMaxHeld of them for at most kMaxHoldS: others
//             are dropped, "no camera_info yet").
//             ~rig_source camchain (default): the model from ~camchain/~mount.
//             image (sensor_msgs/Image, the reference camera; vehicle.launch
//             remaps it; ~intensity false: not subscribed): its grey at the
//             depth frame's stamp is fused into the voxels (the mesh's
//             intensity colour); a depth frame without one fuses without.
//             depth_masked/vehicles (TrackedVehicleArray, optional): the
//             regions of parked vehicles that drove off (carve_min/max), carved
//             free in the depth maps fused within 2 s after it (no ghost).
// Publishes   tsdf/mesh  (visualization_msgs/MarkerArray: one TRIANGLE_LIST per map
//                    block, only blocks changed since the last publish)
//             tsdf/cloud (sensor_msgs/PointCloud2: surface points, world frame,
//                    fields x y z intensity (the voxels' grey; 0 = none))
//             tsdf/occupancy (nav_msgs/OccupancyGrid, world frame, latched:
//                    the ground-aware obstacle grid around base_frame every
//                    ~occupancy_period s; core/tsdf/occupancy_grid.h)
//             /diagnostics (StageMonitor "tsdf": rates, integration time, drops
//                    by reason, tf failures; frames, errors caught, lost swap
//                    blocks, saves, block counts)
// Services    ~save_mesh, ~save_cloud, ~save_map, ~load_map (FilePath: a
//             path relative to ~save_directory ($ROS_HOME/fisheye_mapping by
//             default), or an absolute one; empty is an error; a save outside
//             the folder is refused unless ~allow_any_save_path (unsafe); a
//             link at the target is replaced, never followed; a FIFO or a
//             device refused; every save verified (fsync, size, close)),
//             ~clear_map (std_srvs/Trigger)
// Parameters  see docs/nodelets.md ("fisheye_mapping/TsdfFusion"); max_range,
//             min_observations and publish_period also through
//             dynamic_reconfigure (cfg/TsdfFusion.cfg).
//
// Nothing the user built is lost: every exception in a callback is caught,
// logged with the frame stamp and counted (the stage goes on); SIGTERM saves
// like SIGINT; the shutdown/autosave file is never replaced by an empty map,
// and its previous version is kept as <path>.1; ~reload_map_on_start resumes
// from it; a depth stamp far older than the last one (bag replayed, clock
// reset) resets the time state and keeps the map (or clears it on request).
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>

#include <dynamic_reconfigure/server.h>
#include <deque>

#include <image_transport/image_transport.h>
#include <message_filters/subscriber.h>
#include <nav_msgs/OccupancyGrid.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/message_filter.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/MarkerArray.h>

#include "fisheye_mapping/TrackedVehicleArray.h"
#include "fisheye_mapping/FilePath.h"
#include "fisheye_mapping/FrameDone.h"
#include "fisheye_mapping/TsdfFusionConfig.h"
#include "fisheye_mapping/core/tsdf/occupancy_grid.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"
#include "fisheye_mapping/core/tsdf/tsdf_mesher.h"
#include "fisheye_mapping/ros/camera_info.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/mesh_markers.h"
#include "fisheye_mapping/core/common/stream_timeline.h"
#include "fisheye_mapping/core/tsdf/map_session.h"
#include "fisheye_mapping/ros/node_options.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_monitor.h"
#include "fisheye_mapping/ros/tsdf_node_helpers.h"

namespace fisheye_mapping {

using tsdf_node::acquireSigterm;
using tsdf_node::releaseSigterm;

class TsdfFusionNodelet : public nodelet::Nodelet {
 public:
  ~TsdfFusionNodelet() override {
    autosave_timer_.stop();
    timer_.stop();
    occupancy_timer_.stop();
    hold_timer_.stop();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (map_ && session_) session_->shutdown(*map_);
    }
    if (sigterm_acquired_) releaseSigterm();
  }

 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    int queue_size = 10;
    TsdfConfig cfg;
    try {
      // Every parameter is declared once: the map's in TsdfConfig, the node's
      // own (frames, persistence, time resets) in TsdfNodeOptions.
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
      world_frame_ = opts_.world_frame;
      base_frame_ = opts_.base_frame;
      reload_on_start_ = opts_.reload_map_on_start;
      autosave_period_ = opts_.autosave_period;
      clear_on_time_reset_ = opts_.clear_map_on_time_reset;
      time_reset_threshold_ = opts_.time_reset.time_reset_threshold;
      timeline_ = std::make_unique<StreamTimeline>(1, time_reset_threshold_);
      publish_period_ = opts_.publish_period;
      queue_size = opts_.queue_size;
      rig_source_ = opts_.rig.rig_source;
      // Inside the save folder, like the services' paths (else refused:
      // the stage does not start).
      // The map file's policy (save on shutdown, .1 backup, reload, autosave)
      // is the core's MapSession.
      session_ = std::make_unique<MapSession>(
          opts_.save_map_on_shutdown.empty() ? std::string()
                                             : confineSavePath(opts_.save_map_on_shutdown, save_folder_),
          [this](bool error, const std::string& message) { say(error, message); });
      cfg = TsdfConfig::fromParams(RosParams(pnh));
      if (!opts_.rig.fromCameraInfo()) rig_ = loadRigFromParams(pnh);
      monitor_ = std::make_unique<StageMonitor>(nh, pnh, "tsdf");
      live_ = cfg;
      map_ = std::make_unique<TsdfMap>(cfg);
    } catch (const std::exception& e) {
      NODELET_ERROR("TSDF fusion not started: %s", e.what());
      return;
    }
    map_->setSwapErrorCallback([this](bool lost, const std::string& message) {
      // Called with mutex_ held, from the map: log and count only.
      if (lost) {
        NODELET_ERROR("%s", message.c_str());  // once per block: it is gone afterwards
      } else {
        NODELET_ERROR_THROTTLE(5.0, "%s (%zu swap writes failed so far)", message.c_str(),
                               map_->numSwapWriteFailures());
      }
    });
    mesher_ = std::make_unique<TsdfMesher>(cfg.min_observations);
    mesh_markers_ = std::make_unique<MeshMarkerStream>(world_frame_, cfg.colour);
    if (session_->start(*map_, reload_on_start_)) {
      mesher_->clear();
      cloud_stale_ = true;
    }
    sigterm_acquired_ = true;
    NODELET_INFO("%s", acquireSigterm().c_str());

    tf_buffer_ = std::make_unique<tf2_ros::Buffer>(ros::Duration(30.0));
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
    if (rig_source_ == "camera_info") {
      info_sub_ = nh.subscribe("depth_masked/camera_info", 10, &TsdfFusionNodelet::onCameraInfo, this);
      // Frames held for their CameraInfo longer than kMaxHoldS are dropped
      // (and acknowledged: a paced player waits for them).
      hold_timer_ = nh.createWallTimer(ros::WallDuration(0.25), [this](const ros::WallTimerEvent&) {
        std::lock_guard<std::mutex> order(order_mutex_);
        std::vector<sensor_msgs::ImageConstPtr> expired;
        {
          std::lock_guard<std::mutex> lock(info_mutex_);
          const ros::WallTime now = ros::WallTime::now();
          while (!held_.empty() && (now - held_.front().second).toSec() > kMaxHoldS) {
            expired.push_back(held_.front().first);
            held_.pop_front();
          }
          takeReadyLocked(&expired);
        }
        for (const auto& m : expired) processDepth(m);  // no model yet: dropped, "no camera_info yet"
      });
    }
    vehicles_sub_ = nh.subscribe("depth_masked/vehicles", 5, &TsdfFusionNodelet::onVehicles, this);
    if (opts_.intensity) {
      it_ = std::make_unique<image_transport::ImageTransport>(nh);
      image_sub_ = it_->subscribe("image", 4, &TsdfFusionNodelet::onImage, this);
    }
    depth_sub_.subscribe(nh, "depth_masked/image", queue_size);
    depth_sub_.registerCallback([this](const sensor_msgs::ImageConstPtr&) { monitor_->input(); });
    tf_filter_ = std::make_unique<tf2_ros::MessageFilter<sensor_msgs::Image>>(depth_sub_, *tf_buffer_, world_frame_,
                                                                              queue_size, nh);
    tf_filter_->registerCallback(&TsdfFusionNodelet::onDepth, this);
    tf_filter_->registerFailureCallback([this](const sensor_msgs::ImageConstPtr& msg,
                                               tf2_ros::filter_failure_reasons::FilterFailureReason reason) {
      try {
        noteTfFilterFailure(*msg, reason);
        {
          // A bag played again: its tf lies before the cache's newest data, so
          // frames fail here and never reach onDepth.
          std::lock_guard<std::mutex> lock(mutex_);
          handleTimeReset(msg->header.stamp);
        }
        done(msg->header, "no transform from '" + msg->header.frame_id + "' to '" + world_frame_ + "'");
      } catch (const std::exception& e) {
        noteException(depth_errors_, "tf failure", msg->header.stamp, e.what());
      } catch (...) {
        noteException(depth_errors_, "tf failure", msg->header.stamp, "unknown exception");
      }
    });
    // Only changed blocks go out on each update; a subscriber that connects
    // later (rviz started mid-drive) is first sent the whole mesh.
    mesh_pub_ = nh.advertise<visualization_msgs::MarkerArray>(
        "tsdf/mesh", 16, [this](const ros::SingleSubscriberPublisher& pub) {
          guarded(timer_errors_, "mesh subscriber connect", [&] { onMeshSubscriber(pub); });
        });
    cloud_pub_ = nh.advertise<sensor_msgs::PointCloud2>("tsdf/cloud", 2, true);
    occupancy_pub_ = nh.advertise<nav_msgs::OccupancyGrid>("tsdf/occupancy", 1, true);
    if (opts_.occupancy_period > 0) {
      occupancy_timer_ = nh.createWallTimer(ros::WallDuration(opts_.occupancy_period), [this](const ros::WallTimerEvent&) {
        guarded(timer_errors_, "occupancy timer", [this] { publishOccupancy(); });
      });
    }
    // One FrameDone per depth frame finished with (fused or skipped): the
    // paced bag player waits for it.
    done_pub_ = nh.advertise<fisheye_mapping::FrameDone>("tsdf/fusion_done", 100);
    services_.push_back(pnh.advertiseService("save_mesh", &TsdfFusionNodelet::saveMesh, this));
    services_.push_back(pnh.advertiseService("save_cloud", &TsdfFusionNodelet::saveCloud, this));
    services_.push_back(pnh.advertiseService("save_map", &TsdfFusionNodelet::saveMap, this));
    services_.push_back(pnh.advertiseService("load_map", &TsdfFusionNodelet::loadMap, this));
    services_.push_back(pnh.advertiseService("clear_map", &TsdfFusionNodelet::clearMap, this));
    timer_ = nh.createWallTimer(ros::WallDuration(publish_period_), [this](const ros::WallTimerEvent&) {
      guarded(timer_errors_, "publish timer", [this] { publish(); });
    });
    if (autosave_period_ > 0.0) {
      if (!session_->enabled()) {
        NODELET_WARN("~autosave_period %.1f s ignored: ~save_map_on_shutdown is not set", autosave_period_);
      } else {
        autosave_timer_ = nh.createWallTimer(ros::WallDuration(autosave_period_), [this](const ros::WallTimerEvent&) {
          guarded(timer_errors_, "autosave timer", [this] { autosave(); });
        });
      }
    }
    monitor_->setExtraReport([this](diagnostic_updater::DiagnosticStatusWrapper& stat) { diagnose(stat); });
    // After the timer exists: the first callback (the start-up values) may set its period.
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<TsdfFusionConfig>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](TsdfFusionConfig& c, uint32_t) {
      guarded(service_errors_, "reconfigure", [&] { onReconfigure(c); });
    });
    NODELET_INFO("TSDF fusion: voxel %.3f m, truncation %.3f m, local map %.0fx%.0fx%.0f m, %s integrator",
                 cfg.voxel_size, cfg.truncation(), cfg.local_map_size.x(), cfg.local_map_size.y(), cfg.local_map_size.z(),
                 toString(cfg.integrator));
  }

  // dynamic_reconfigure (cfg/TsdfFusion.cfg): the map's run-time parameters
  // (TsdfConfig) and the node's (publish_period), each checked against its
  // declaration. A value outside its range is refused: the running values
  // stay and are reported back. Only what applies without rebuilding the map
  // is run-time.
  void onReconfigure(TsdfFusionConfig& c) {
    dynamic_reconfigure::Config values;
    c.__toMessage__(values);
    std::lock_guard<std::mutex> lock(mutex_);
    std::string error;
    std::optional<TsdfConfig> next = reconfigured(TsdfConfig::params(), live_, values, error);
    std::optional<TsdfNodeOptions> node;
    if (next) node = reconfigured(TsdfNodeOptions::params(), opts_, values, error);
    if (!next || !node) {
      keepRunningValues(c, std::make_pair(std::cref(TsdfConfig::params()), live_),
                        std::make_pair(std::cref(TsdfNodeOptions::params()), opts_));
      NODELET_ERROR("reconfigure refused, running values kept: %s", error.c_str());
      monitor_->error("reconfigure refused: " + error);
      return;
    }
    if (next->min_observations != live_.min_observations) {
      mesher_->setMinObservations(next->min_observations);
      mesh_markers_->markChanged(mesher_->rebuild(*map_));
      cloud_stale_ = true;
    }
    map_->setMaxRange(next->max_range);
    live_ = *next;
    if (node->publish_period != publish_period_) timer_.setPeriod(ros::WallDuration(publish_period_ = node->publish_period));
    opts_ = *node;
    NODELET_INFO("reconfigured: max_range %.2f m (0: none), min_observations %d, publish_period %.2f s",
                 live_.max_range, live_.min_observations, publish_period_);
  }

  // Runs fn; an exception is logged with the last frame's stamp, counted, and
  // the stage goes on.
  template <typename Fn>
  void guarded(std::atomic<size_t>& counter, const char* where, Fn fn) {
    try {
      fn();
    } catch (const std::exception& e) {
      noteException(counter, where, last_stamp_seen_, e.what());
    } catch (...) {
      noteException(counter, where, last_stamp_seen_, "unknown exception");
    }
  }

  void noteException(std::atomic<size_t>& counter, const char* where, const ros::Time& stamp, const std::string& what) {
    ++counter;
    if (monitor_) monitor_->error(std::string(where) + ": " + what);
    NODELET_ERROR("exception in the %s callback (frame stamp %.3f): %s; caught, the stage goes on (%zu so far there)",
                  where, stamp.toSec(), what.c_str(), static_cast<size_t>(counter));
  }

  // Logs through rosconsole, or on stderr once roscpp has shut down (its
  // console goes with it), as during the shutdown save.
  void say(bool error, const std::string& message) {
    if (ros::ok()) {
      if (error) {
        NODELET_ERROR("%s", message.c_str());
      } else {
        NODELET_INFO("%s", message.c_str());
      }
    } else {
      std::fprintf(stderr, "[%s] [%s]: %s\n", error ? "ERROR" : " INFO", getName().c_str(), message.c_str());
    }
  }

  void autosave() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (map_) session_->autosave(*map_);
  }

  // Time went backwards by more than time_reset_threshold_ (a bag played
  // again, a sim clock reset): forget the time state (last stamp, tf cache)
  // and keep the map, or clear it with ~clear_map_on_time_reset. mutex_ held.
  bool handleTimeReset(const ros::Time& stamp) {
    // The one time-reset unit of every stage (StreamTimeline; threshold 0: never).
    const StreamTimeline::Event ev = timeline_->observe(0, std::int64_t(stamp.toNSec()));
    if (ev.kind != StreamTimeline::Kind::kReset) return false;
    monitor_->timeReset("depth frames: " + ev.reason);
    NODELET_WARN("depth frames: %s; tf cache cleared, %s", ev.reason.c_str(),
                 clear_on_time_reset_ ? "map cleared (~clear_map_on_time_reset)"
                                      : "map kept (~clear_map_on_time_reset: false; call ~clear_map to start afresh)");
    last_stamp_ = ros::Time();
    tf_buffer_->clear();
    if (clear_on_time_reset_) {
      map_->clear();
      clearMesh();
      session_->changed();
    }
    return true;
  }

  // The mesher and the markers forgotten (mutex_ held): rviz gets a DELETEALL.
  void clearMesh() {
    mesher_->clear();
    mesh_pub_.publish(mesh_markers_->clear());
    cloud_stale_ = true;  // the next publish sends the (empty) cloud
  }

  // A frame the tf2 MessageFilter gave up on: a drop, and a tf failure where
  // the pose is what is missing.
  void noteTfFilterFailure(const sensor_msgs::Image& msg, tf2_ros::filter_failure_reasons::FilterFailureReason reason) {
    using tf2_ros::filter_failure_reasons::EmptyFrameID;
    using tf2_ros::filter_failure_reasons::OutTheBack;
    if (reason == EmptyFrameID) {
      monitor_->dropped("bad image");
      NODELET_WARN_THROTTLE(5.0, "depth frame at %.3f has no frame_id; dropped", msg.header.stamp.toSec());
      return;
    }
    const std::string why = reason == OutTheBack ? "older than the tf buffer" : "tf never arrived (or queue full)";
    monitor_->dropped("no pose");
    monitor_->tfFailure("'" + msg.header.frame_id + "' -> '" + world_frame_ + "' at " +
                        std::to_string(msg.header.stamp.toSec()) + ": " + why);
    NODELET_WARN_THROTTLE(5.0, "depth frame at %.3f (frame '%s') dropped: no transform to '%s' (%s)",
                          msg.header.stamp.toSec(), msg.header.frame_id.c_str(), world_frame_.c_str(), why.c_str());
  }

  // The stage's own values after StageMonitor's (rates, drops, tf failures,
  // time resets, callback errors); runs on the monitor's timer thread.
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    std::lock_guard<std::mutex> lock(mutex_);
    const size_t lost = map_->numLostBlocks(), write_failures = map_->numSwapWriteFailures();
    if (lost) stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, "swapped blocks lost");
    if (write_failures) stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, "swap writes failed (blocks kept in RAM)");
    if (session_->savesFailed()) stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, "saves failed");
    stat.add("rig source", rig_source_);
    stat.add("frames fused", frames_fused_);
    stat.add("exceptions in depth callbacks", static_cast<size_t>(depth_errors_));
    stat.add("exceptions in services", static_cast<size_t>(service_errors_));
    stat.add("failed service requests", static_cast<size_t>(service_failures_));
    stat.add("exceptions in timers", static_cast<size_t>(timer_errors_));
    stat.add("lost swapped blocks", lost);
    stat.add("swap write failures", write_failures);
    stat.add("blocks", map_->numBlocks());
    stat.add("active blocks", map_->numActiveBlocks());
    stat.add("mesh blocks on screen", mesh_markers_->numShown());
    stat.add("saves to save_map_on_shutdown", session_->savesOk());
    stat.add("failed saves", session_->savesFailed());
    stat.add("max_range (m)", live_.max_range);
    stat.add("min_observations", live_.min_observations);
    stat.add("frames fused with intensity", frames_with_intensity_);
    stat.add("intensity images unreadable", static_cast<size_t>(image_errors_));
    stat.add("occupancy cells occupied / free / unknown",
             std::to_string(occupancy_cells_[0]) + " / " + std::to_string(occupancy_cells_[1]) + " / " +
                 std::to_string(occupancy_cells_[2]));
    if (const std::string e = session_->lastError(); !e.empty()) stat.add("last save error", e);
  }

  // Tells the paced player that this depth frame is finished with.
  void done(const std_msgs::Header& header, const std::string& skipped_because) {
    fisheye_mapping::FrameDone msg;
    msg.header = header;
    msg.fused = skipped_because.empty();
    msg.reason = skipped_because;
    done_pub_.publish(msg);
  }

  // ~rig_source camera_info: a depth frame that comes before the first
  // CameraInfo of its frame (the other stage publishes both; they race)
  // waits for it (onCameraInfo fuses it); at most kMaxHeld wait, an older
  // one is dropped ("no camera_info yet") and acknowledged.
  static constexpr size_t kMaxHeld = 8;
  static constexpr double kMaxHoldS = 2.0;  // wall time a frame waits at most
  // Frames are fused in the order they came: a frame behind held ones waits
  // with them, and order_mutex_ keeps a flush and a new frame from passing
  // each other.
  void onDepth(const sensor_msgs::ImageConstPtr& msg) {
    std::lock_guard<std::mutex> order(order_mutex_);
    std::vector<sensor_msgs::ImageConstPtr> ready;
    if (rig_source_ == "camera_info") {
      std::lock_guard<std::mutex> lock(info_mutex_);
      if (!models_.count(msg->header.frame_id) || !held_.empty()) {
        held_.emplace_back(msg, ros::WallTime::now());
        // The oldest beyond kMaxHeld goes on (fused if its model has come, else dropped).
        while (held_.size() > kMaxHeld) {
          ready.push_back(held_.front().first);
          held_.pop_front();
        }
        takeReadyLocked(&ready);
      } else {
        ready.push_back(msg);
      }
    } else {
      ready.push_back(msg);
    }
    for (const auto& m : ready) processDepth(m);
  }

  // Moves the held frames at the front whose camera model has come to *ready
  // (info_mutex_ held).
  void takeReadyLocked(std::vector<sensor_msgs::ImageConstPtr>* ready) {
    while (!held_.empty() && models_.count(held_.front().first->header.frame_id)) {
      ready->push_back(held_.front().first);
      held_.pop_front();
    }
  }

  void processDepth(const sensor_msgs::ImageConstPtr& msg) {
    std::string skipped = "not fused";
    struct Ack {  // every path out of here acknowledges the frame
      TsdfFusionNodelet* self;
      const std_msgs::Header& header;
      std::string& why;
      ~Ack() {
        try {
          self->done(header, why);
        } catch (...) {
        }
      }
    } ack{this, msg->header, skipped};
    last_stamp_seen_ = msg->header.stamp;
    try {
      fuse(msg, &skipped);
    } catch (const std::exception& e) {
      skipped = std::string("error: ") + e.what();
      monitor_->dropped("error");
      noteException(depth_errors_, "depth", msg->header.stamp, e.what());
    } catch (...) {
      skipped = "error: unknown exception";
      monitor_->dropped("error");
      noteException(depth_errors_, "depth", msg->header.stamp, "unknown exception");
    }
  }

  void fuse(const sensor_msgs::ImageConstPtr& msg, std::string* skipped_because) {
    std::string& skipped = *skipped_because;
    const std::shared_ptr<const CameraModel> model = modelOf(msg->header.frame_id, &skipped);
    if (!model) return;
    try {
      checkDepthImage(*msg, getNodeHandle().resolveName("depth_masked/image"));
    } catch (const ImageConversionError& e) {
      skipped = e.what();
      monitor_->dropped("bad image");
      NODELET_WARN_THROTTLE(5.0, "%s; frame skipped", e.what());
      return;
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (handleTimeReset(msg->header.stamp)) {
        // Its pose came from the tf cache of the old time line.
        skipped = "time went backwards: time state reset, frame skipped";
        monitor_->dropped("time reset");
        return;
      }
      if (!last_stamp_.isZero() && msg->header.stamp < last_stamp_) {
        skipped = "stamp older than the last fused frame (out of order)";
        monitor_->dropped("out of order");
        NODELET_WARN_THROTTLE(5.0, "depth stamp %.3f is older than the last fused one (%.3f) by less than %.1f s: "
                              "frame out of order, skipped",
                              msg->header.stamp.toSec(), last_stamp_.toSec(), time_reset_threshold_);
        return;
      }
    }
    Eigen::Isometry3d T_W_C, T_W_B;
    try {
      T_W_C = toIsometry(tf_buffer_->lookupTransform(world_frame_, msg->header.frame_id, msg->header.stamp));
      T_W_B = toIsometry(tf_buffer_->lookupTransform(world_frame_, base_frame_, msg->header.stamp));
    } catch (const tf2::TransformException& e) {
      skipped = std::string("no pose: ") + e.what();
      monitor_->dropped("no pose");
      monitor_->tfFailure(e.what());
      NODELET_WARN_THROTTLE(5.0, "no pose for the depth frame at %.3f: %s; frame skipped", msg->header.stamp.toSec(), e.what());
      return;
    }
    cv::Mat depth;
    try {
      depth = toDepthShare(msg);
    } catch (const ImageConversionError& e) {
      skipped = std::string("unreadable depth image: ") + e.what();
      monitor_->dropped("bad image");
      NODELET_WARN_THROTTLE(5.0, "cannot read the depth image: %s; frame skipped", e.what());
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    try {
      const double t0 = StageStats::now();
      const cv::Mat grey = greyFor(*msg, *model);
      const auto stats =
          map_->integrate(depth, *model, T_W_C, T_W_B.translation(), carveFor(msg->header.stamp), grey);
      if (!grey.empty()) ++frames_with_intensity_;
      last_T_W_B_ = T_W_B;
      have_pose_ = true;
      monitor_->processed(StageStats::now() - t0);
      monitor_->output();  // the stage's product: a frame in the map
      last_stamp_ = msg->header.stamp;
      ++frames_fused_;
      session_->changed();
      skipped.clear();
      NODELET_DEBUG("fused frame %.3f: %zu valid pixels, %zu blocks", msg->header.stamp.toSec(), stats.valid_pixels,
                    stats.blocks_touched);
      if (stats.blocks_lost) {
        NODELET_WARN("frame %.3f: %zu swapped blocks could not be read back and are lost (%zu so far)",
                     msg->header.stamp.toSec(), stats.blocks_lost, map_->numLostBlocks());
      }
    } catch (const std::invalid_argument& e) {
      skipped = e.what();
      monitor_->dropped("rejected by the map");
      NODELET_WARN_THROTTLE(5.0, "depth frame at %.3f skipped: %s", msg->header.stamp.toSec(), e.what());
    }
  }

  // The reference camera's images, kept a few frames for the depth frames of
  // their stamps (the depth stage is slower than the camera).
  void onImage(const sensor_msgs::ImageConstPtr& msg) {
    try {
      const cv::Mat grey = toCvImageShare(msg, ImageTarget::kGrey8, getNodeHandle().resolveName("image"));
      std::lock_guard<std::mutex> lock(image_mutex_);
      images_.push_back({msg->header.stamp, msg->header.frame_id, grey, msg});
      while (images_.size() > 8) images_.pop_front();
    } catch (const std::exception& e) {
      ++image_errors_;
      NODELET_WARN_THROTTLE(5.0, "intensity image skipped (the map is fused without its grey): %s", e.what());
    }
  }

  // The grey image of the depth frame's stamp (within 1 ms) and camera, the
  // camera's size; empty when there is none (the frame fuses without intensity).
  cv::Mat greyFor(const sensor_msgs::Image& depth, const CameraModel& model) {
    std::lock_guard<std::mutex> lock(image_mutex_);
    for (auto it = images_.rbegin(); it != images_.rend(); ++it) {
      if (std::abs((it->stamp - depth.header.stamp).toSec()) > 1e-3) continue;
      if (it->grey.cols != model.width() || it->grey.rows != model.height()) {
        NODELET_WARN_THROTTLE(5.0, "intensity image is %dx%d, the depth camera %dx%d: fused without intensity",
                              it->grey.cols, it->grey.rows, model.width(), model.height());
        return cv::Mat();
      }
      return it->grey.clone();  // the entry (and its message) may go before the frame is fused
    }
    return cv::Mat();
  }

  // The obstacle grid around the vehicle's last fused pose.
  void publishOccupancy() {
    nav_msgs::OccupancyGrid msg;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!have_pose_ || occupancy_pub_.getNumSubscribers() == 0) return;
      const OccupancyGrid grid =
          computeOccupancyGrid(*map_, last_T_W_B_.translation(), opts_.occupancy, live_.min_observations);
      msg.header.frame_id = world_frame_;
      msg.header.stamp = last_stamp_;
      msg.info.map_load_time = last_stamp_;
      msg.info.resolution = static_cast<float>(grid.resolution);
      msg.info.width = static_cast<uint32_t>(grid.width);
      msg.info.height = static_cast<uint32_t>(grid.height);
      msg.info.origin.position.x = grid.origin.x();
      msg.info.origin.position.y = grid.origin.y();
      // The grid lies at the vehicle's ground (its base), for rviz.
      msg.info.origin.position.z = last_T_W_B_.translation().z();
      msg.info.origin.orientation.w = 1.0;
      msg.data.assign(grid.cells.begin(), grid.cells.end());
      occupancy_cells_ = {grid.occupied, grid.free, grid.unknown};
    }
    occupancy_pub_.publish(msg);
  }

  // The camera model of depth images in `frame`: the camchain camera of that
  // frame id, or (~rig_source camera_info) the latest CameraInfo's. Null:
  // none, the drop counted and *skipped saying why.
  std::shared_ptr<const CameraModel> modelOf(const std::string& frame, std::string* skipped) {
    if (rig_source_ == "camera_info") {
      std::lock_guard<std::mutex> lock(info_mutex_);
      const auto it = models_.find(frame);
      if (it != models_.end()) return it->second.model;
      *skipped = "no camera_info for frame '" + frame + "' yet";
      monitor_->dropped("no camera_info yet");
      NODELET_WARN_THROTTLE(5.0, "depth frame '%s' dropped: no CameraInfo of that frame on %s yet", frame.c_str(),
                            getNodeHandle().resolveName("depth_masked/camera_info").c_str());
      return nullptr;
    }
    for (const auto& cam : rig_.cameras) {
      if (cam.frame_id == frame) return std::shared_ptr<const CameraModel>(std::shared_ptr<void>(), &cam.model);
    }
    *skipped = "frame '" + frame + "' is not a camera of the rig";
    monitor_->dropped("not a rig camera");
    NODELET_WARN_THROTTLE(5.0, "depth frame '%s' is not a camera of the rig; frame skipped", frame.c_str());
    return nullptr;
  }

  // ~rig_source camera_info: the model of the CameraInfo's frame, parsed
  // again only when the calibration changes; a bad one is logged and counted,
  // and that frame's depth is dropped until a good one arrives.
  void onCameraInfo(const sensor_msgs::CameraInfoConstPtr& msg) {
    std::lock_guard<std::mutex> order(order_mutex_);
    std::vector<sensor_msgs::ImageConstPtr> ready;  // held depth frames whose model has come, fused below
    {
      std::lock_guard<std::mutex> lock(info_mutex_);
      const auto it = models_.find(msg->header.frame_id);
      if (it != models_.end() && sameCalibration(it->second.info, *msg)) return;
      try {
        models_[msg->header.frame_id] = {*msg, std::make_shared<const CameraModel>(fromCameraInfo(*msg))};
        NODELET_INFO("camera model of frame '%s' from its CameraInfo (%s, %ux%u)", msg->header.frame_id.c_str(),
                     msg->distortion_model.c_str(), msg->width, msg->height);
        takeReadyLocked(&ready);
      } catch (const std::exception& e) {
        models_.erase(msg->header.frame_id);
        monitor_->error(std::string("camera_info: ") + e.what());
        NODELET_ERROR_THROTTLE(5.0, "camera_info rejected: %s", e.what());
      }
    }
    for (const auto& m : ready) processDepth(m);
  }

  // Every publish_period: the mesh blocks that changed, and the cloud.
  void publish() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!map_) return;
    const std::vector<BlockIndex> changed = mesher_->update(*map_);
    const ros::Time stamp = meshStamp();
    const visualization_msgs::MarkerArray markers = mesh_markers_->update(mesher_->blocks(), changed, stamp);
    if (!markers.markers.empty()) mesh_pub_.publish(markers);
    if (changed.empty() && !cloud_stale_) return;
    cloud_pub_.publish(toCloudMsg(mesher_->surfaceCloud(), world_frame_, stamp));
    cloud_stale_ = false;
  }

  ros::Time meshStamp() const { return last_stamp_.isZero() ? ros::Time::now() : last_stamp_; }

  // A late subscriber (rviz started mid-drive) gets what the others have:
  // pending changes are sent to everyone first, then the whole mesh to it.
  void onMeshSubscriber(const ros::SingleSubscriberPublisher& pub) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!mesher_) return;
    const ros::Time stamp = meshStamp();
    const visualization_msgs::MarkerArray pending =
        mesh_markers_->update(mesher_->blocks(), mesher_->update(*map_), stamp);
    if (!pending.markers.empty()) mesh_pub_.publish(pending);
    pub.publish(mesh_markers_->republishAll(mesher_->blocks(), stamp));
  }

  // A FilePath service: `requested` resolved (a save: confined to the save
  // folder; a load: relative to it; empty: an error), fn run on the absolute
  // path under mutex_; the response and the log say what was done where, or
  // why not (the OS error of a failed write among it).
  enum class Access { kSave, kLoad };
  template <typename Fn>
  bool run(fisheye_mapping::FilePath::Response& res, const std::string& requested, const char* what, Fn fn,
           Access access = Access::kSave) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!map_) {
      res.success = false;
      res.message = "the TSDF fusion did not start (see its error log)";
      return true;
    }
    try {
      const std::string path = access == Access::kSave ? confineSavePath(requested, save_folder_)
                                                       : tsdf_node::inputPath(requested, save_folder_);
      fn(path);
      res.success = true;
      res.message = std::string(what) + " " + path + ": done";
      NODELET_INFO("%s", res.message.c_str());
    } catch (const std::exception& e) {
      res.success = false;
      res.message = std::string(what) + " '" + requested + "' failed: " + e.what();
      ++service_failures_;
      NODELET_ERROR("%s (last frame stamp %.3f); %zu failed requests so far", res.message.c_str(),
                    last_stamp_.toSec(), static_cast<size_t>(service_failures_));
    } catch (...) {
      res.success = false;
      res.message = std::string(what) + " '" + requested + "': unknown exception";
      noteException(service_errors_, what, last_stamp_, "unknown exception");
    }
    return true;
  }

  // The exports read the mesher: bring it up to date, and let the next
  // publish send those blocks to rviz.
  bool saveMesh(fisheye_mapping::FilePath::Request& req, fisheye_mapping::FilePath::Response& res) {
    return run(res, req.path, "save mesh to", [this](const std::string& p) {
      mesh_markers_->markChanged(mesher_->update(*map_));
      MeshExportOptions options;
      options.coloring = live_.colour;
      mesher_->saveMeshPly(p, options);
    });
  }
  bool saveCloud(fisheye_mapping::FilePath::Request& req, fisheye_mapping::FilePath::Response& res) {
    return run(res, req.path, "save cloud to", [this](const std::string& p) {
      mesh_markers_->markChanged(mesher_->update(*map_));
      mesher_->saveCloudPcd(p);
    });
  }
  bool saveMap(fisheye_mapping::FilePath::Request& req, fisheye_mapping::FilePath::Response& res) {
    return run(res, req.path, "save map to", [this](const std::string& p) { map_->save(p); });
  }
  bool loadMap(fisheye_mapping::FilePath::Request& req, fisheye_mapping::FilePath::Response& res) {
    // The file is read and checked whole before the live map is replaced.
    return run(res, req.path, "load map from", [this](const std::string& p) {
      map_->load(p);
      session_->changed();
      clearMesh();
    }, Access::kLoad);
  }
  bool clearMap(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!map_) return res.success = false, res.message = "the TSDF fusion did not start", true;
    try {
      map_->clear();
      clearMesh();
      last_stamp_ = ros::Time();
      timeline_->reset();
      session_->changed();
      res.success = true;
      res.message = "map cleared";
    } catch (const std::exception& e) {
      res.success = false;
      res.message = std::string("clear failed: ") + e.what();
      noteException(service_errors_, "clear_map", last_stamp_, e.what());
    }
    return true;
  }

  // The depth mask's regions to carve (parked vehicles that drove off), in
  // the map's frame; another frame is refused once, named in the log.
  void onVehicles(const TrackedVehicleArrayConstPtr& msg) {
    std::lock_guard<std::mutex> lock(carve_mutex_);
    if (msg->world_frame != world_frame_) {
      NODELET_WARN_ONCE("depth_masked/vehicles is in frame '%s', the map in '%s': its carve regions are ignored",
                        msg->world_frame.c_str(), world_frame_.c_str());
      return;
    }
    carve_.clear();
    for (size_t i = 0; i < msg->carve_min.size() && i < msg->carve_max.size(); ++i) {
      const auto& a = msg->carve_min[i];
      const auto& b = msg->carve_max[i];
      carve_.emplace_back(Eigen::Vector3d(a.x, a.y, a.z), Eigen::Vector3d(b.x, b.y, b.z));
    }
    carve_stamp_ = msg->header.stamp;
  }
  // The latest regions, for a depth map within 2 s of them.
  std::vector<Eigen::AlignedBox3d> carveFor(const ros::Time& stamp) {
    std::lock_guard<std::mutex> lock(carve_mutex_);
    if (carve_.empty() || std::abs((stamp - carve_stamp_).toSec()) > 2.0) return {};
    return carve_;
  }

  std::mutex carve_mutex_;
  std::vector<Eigen::AlignedBox3d> carve_;
  ros::Time carve_stamp_;
  ros::Subscriber vehicles_sub_;
  std::mutex mutex_;
  std::string rig_source_ = "camchain";
  Rig rig_;  // camchain source
  // camera_info source: frame id -> its latest CameraInfo and camera model.
  struct InfoModel {
    sensor_msgs::CameraInfo info;
    std::shared_ptr<const CameraModel> model;
  };
  std::mutex info_mutex_;
  std::map<std::string, InfoModel> models_;
  // Depth frames waiting for their first CameraInfo, with when they came (info_mutex_).
  std::deque<std::pair<sensor_msgs::ImageConstPtr, ros::WallTime>> held_;
  ros::WallTimer hold_timer_;
  std::mutex order_mutex_;  // taken first: depth frames are fused one at a time, in the order they came
  ros::Subscriber info_sub_;
  std::unique_ptr<TsdfMap> map_;
  std::unique_ptr<TsdfMesher> mesher_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  message_filters::Subscriber<sensor_msgs::Image> depth_sub_;
  std::unique_ptr<tf2_ros::MessageFilter<sensor_msgs::Image>> tf_filter_;
  ros::Publisher mesh_pub_, cloud_pub_, done_pub_, occupancy_pub_;
  ros::WallTimer occupancy_timer_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::Subscriber image_sub_;
  struct StampedGrey {
    ros::Time stamp;
    std::string frame;
    cv::Mat grey;
    sensor_msgs::ImageConstPtr msg;  // keeps the pixels alive: grey may share them
  };
  std::mutex image_mutex_;
  std::deque<StampedGrey> images_;  // image_mutex_
  std::atomic<size_t> image_errors_{0};
  size_t frames_with_intensity_ = 0;  // mutex_
  Eigen::Isometry3d last_T_W_B_ = Eigen::Isometry3d::Identity();  // mutex_
  bool have_pose_ = false;
  std::array<size_t, 3> occupancy_cells_{};  // of the last grid; mutex_
  std::vector<ros::ServiceServer> services_;
  ros::WallTimer timer_, autosave_timer_;
  std::unique_ptr<StageMonitor> monitor_;
  std::unique_ptr<MeshMarkerStream> mesh_markers_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<TsdfFusionConfig>> reconfigure_;
  // The run-time values (cfg/TsdfFusion.cfg) over the start-up config; mutex_.
  TsdfConfig live_;
  TsdfNodeOptions opts_;  // the node's options, publish_period as it runs; mutex_
  std::string world_frame_, base_frame_;
  std::unique_ptr<MapSession> session_;  // the file of save_map_on_shutdown; mutex_
  SaveFolder save_folder_;               // where saves may write (~save_directory)
  bool reload_on_start_ = false, clear_on_time_reset_ = false;
  double autosave_period_ = 0.0, time_reset_threshold_ = 1.0, publish_period_ = 1.0;
  bool sigterm_acquired_ = false;
  ros::Time last_stamp_;
  std::unique_ptr<StreamTimeline> timeline_;  // time resets of the depth frames; mutex_
  ros::Time last_stamp_seen_;  // of the last depth frame received (for error logs)
  size_t frames_fused_ = 0;
  // Exceptions caught per kind of callback; service_failures_: requests
  // answered with an error (bad path, bad map file).
  std::atomic<size_t> depth_errors_{0}, service_errors_{0}, timer_errors_{0}, service_failures_{0};
  bool cloud_stale_ = false;  // the map was cleared or loaded: send the cloud even if no block changed
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::TsdfFusionNodelet, nodelet::Nodelet)
