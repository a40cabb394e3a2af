// Frame-set sync nodelet: groups the rig's camera images into CameraFrameSets.
//
// Subscribes  one image topic per camera of the rig, through image_transport
//             (~image_transport hint), only while `frames` has subscribers.
//             The camera order and topics: ~image_topics (list in camera
//             order), else the camchain's rostopics (~rig_source camchain).
//             With ~rig_source camera_info: each camera's CameraInfo
//             (~camera_info_topics, list in camera order; default the
//             image_transport convention <image topic's namespace>/camera_info,
//             /cam0/image_raw -> /cam0/camera_info) until one of each arrived.
// Publishes   frames (fisheye_mapping/CameraFrameSet): header = the reference
//             (first) camera's image header; images and camera_infos (the
//             rig's calibration, each with its image's header) in camera order.
//             /diagnostics (StageMonitor "sync"): input = images, output
//             = sets; per-camera rates, a silent camera (ERROR naming it), bad
//             images, sets out, incomplete / out-of-order / stale drops, mean
//             latency, time resets and callback errors, tf failures.
// Parameters  ~rig_source (camchain | camera_info; default camchain),
//             ~camchain, ~mount (camchain source), ~base_frame (camera_info
//             source: the frame the camera poses are looked up in, default
//             base_link; from /tf_static), ~image_topics, ~camera_info_topics,
//             ~policy (exact | approximate), ~max_interval (s, approximate),
//             ~queue_size (open sets), ~silent_warning (s of ROS time - sim
//             time under a bag - without an image before a camera is
//             reported), ~time_reset_threshold (s, default 1; 0: never reset).
//             The last five also through dynamic_reconfigure (cfg/SyncReconfigure.cfg):
//             a change rebuilds the sync (its open sets are dropped).
// Time going backwards (a bag played again, rosbag play restarted, a sim clock
// reset): an image older than its camera's newest by more than the threshold,
// or a ROS clock (sim time) behind the newest image by more than it, resets
// the sync (core FrameSetSync), with a warning naming both stamps.
// Any number of cameras (message_filters' Synchronizer stops at 9): the
// grouping is the core FrameSetSync. Images whose size differs from the
// calibration, malformed images and images in an encoding that is not a
// camera-image encoding of ros/conversions.h are reported and dropped.
#include <memory>
#include <mutex>
#include <optional>

#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <sensor_msgs/CompressedImage.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/core/sync/frame_sync.h"

#include "fisheye_mapping/SyncReconfigureConfig.h"
#include "fisheye_mapping/ros/camera_info.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/node_options.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_monitor.h"

namespace fisheye_mapping {

namespace {

// image_transport's convention: the CameraInfo next to the image topic.
std::string cameraInfoTopic(const std::string& image_topic) {
  const auto slash = image_topic.rfind('/');
  return slash == std::string::npos ? "camera_info" : image_topic.substr(0, slash) + "/camera_info";
}

}  // namespace

class SyncNodelet : public nodelet::Nodelet {
  using Sync = FrameSetSync<sensor_msgs::ImageConstPtr>;
  using SyncReconfigure = SyncReconfigureConfig;  // the generated class

 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    try {
      // Every sync parameter is declared once, in the core (FrameSyncConfig);
      // the node's own in FrameSyncNodeOptions.
      requireKnownParams(pnh, {FrameSyncConfig::params().names(), FrameSyncNodeOptions::params().names()});
      cfg_ = FrameSyncConfig::fromParams(RosParams(pnh));
      opts_ = FrameSyncNodeOptions::params().read(RosParams(pnh), FrameSyncNodeOptions());
      transport_ = opts_.image_transport;
      initRigSource(pnh);
      sync_ = makeSync(cfg_);
      monitor_ = std::make_unique<StageMonitor>(nh, pnh, "sync");
    } catch (const std::exception& e) {
      NODELET_FATAL("frame sync not started: %s", e.what());
      return;
    }
    cams_.resize(topics_.size());
    for (auto& c : cams_) c.stats = std::make_unique<StageStats>(monitor_->options().window_s);
    monitor_->setExtraReport([this](diagnostic_updater::DiagnosticStatusWrapper& stat) { report(stat); });
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    auto connect = [this](const ros::SingleSubscriberPublisher&) { updateSubscription(); };
    pub_ = nh.advertise<CameraFrameSet>("frames", 5, connect, connect);
    // A subscriber that connected while the publishers above were being
    // assigned may have run the connect callback too early (it saw none):
    // look once more now that all of them exist.
    updateSubscription();
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<SyncReconfigure>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](SyncReconfigure& c, uint32_t) { onReconfigure(c); });
    clock_timer_ = nh.createWallTimer(ros::WallDuration(0.2), [this](const ros::WallTimerEvent&) { checkClock(); });
    std::string list;
    for (const auto& t : topics_) list += " " + t;
    NODELET_INFO("frame sync: %zu cameras (rig from %s, %s policy, max interval %.4f s):%s", topics_.size(),
                 rig_source_.c_str(), toString(cfg_.policy).c_str(), cfg_.max_interval, list.c_str());
  }

  void initRigSource(ros::NodeHandle& pnh) {
    rig_source_ = opts_.rig.rig_source;
    topics_ = cfg_.image_topics;
    if (!opts_.rig.fromCameraInfo()) {
      setRig(loadRigFromParams(pnh));
    } else {
      if (topics_.empty()) throw std::invalid_argument("~rig_source camera_info: set ~image_topics (camera order)");
      base_frame_ = opts_.base_frame;
      subscribeCameraInfos();
    }
  }

  // Camchain source: the topics default to the camchain's rostopics.
  void setRig(Rig rig) {
    if (topics_.empty()) {
      for (const auto& c : rig.cameras) {
        if (c.rostopic.empty()) throw CalibrationError("camera " + c.name + " has no rostopic in the camchain; set ~image_topics");
        topics_.push_back(c.rostopic);
      }
    }
    if (topics_.size() != rig.cameras.size())
      throw CalibrationError("~image_topics has " + std::to_string(topics_.size()) + " topics for " +
                             std::to_string(rig.cameras.size()) + " cameras");
    rig_ = std::move(rig);
  }

  void subscribeCameraInfos() {
    std::vector<std::string> info_topics = opts_.camera_info_topics;
    if (info_topics.empty()) {
      for (const auto& t : topics_) info_topics.push_back(cameraInfoTopic(t));
    }
    if (info_topics.size() != topics_.size())
      throw std::invalid_argument("~camera_info_topics has " + std::to_string(info_topics.size()) + " topics for " +
                                  std::to_string(topics_.size()) + " ~image_topics");
    infos_.resize(topics_.size());
    tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_);
    for (size_t i = 0; i < info_topics.size(); ++i) {
      info_subs_.push_back(getNodeHandle().subscribe<sensor_msgs::CameraInfo>(
          info_topics[i], 1, [this, i](const sensor_msgs::CameraInfoConstPtr& m) { onCameraInfo(m, i); }));
    }
    rig_timer_ = getNodeHandle().createWallTimer(ros::WallDuration(0.5), [this](const ros::WallTimerEvent&) { tryBuildRig(); });
  }

  void onCameraInfo(const sensor_msgs::CameraInfoConstPtr& msg, size_t cam) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!infos_[cam]) infos_[cam] = msg;
  }

  // Camera_info source: once every camera's CameraInfo is in and tf knows
  // each optical frame in the base frame, the rig is built and the
  // CameraInfo subscriptions end. Until then images are dropped ("no rig").
  void tryBuildRig() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (rig_) return;
    std::vector<sensor_msgs::CameraInfo> infos;
    for (const auto& info : infos_) {
      if (!info) return;
      infos.push_back(*info);
    }
    try {
      rig_ = rigFromCameraInfosAndTf(infos, {}, *tf_buffer_, base_frame_, ros::Time(0), 0.0);
      NODELET_INFO("rig of %zu cameras built from their CameraInfo and tf (base frame %s)", infos.size(), base_frame_.c_str());
    } catch (const tf2::TransformException& e) {
      monitor_->tfFailure(e.what());
      NODELET_WARN_THROTTLE(5.0, "%s (yet)", e.what());
      return;
    } catch (const std::exception& e) {
      monitor_->error(std::string("rig from camera_info: ") + e.what());
      NODELET_ERROR_THROTTLE(10.0, "rig from camera_info rejected: %s", e.what());
      return;
    }
    rig_timer_.stop();
    info_subs_.clear();
  }

  std::unique_ptr<Sync> makeSync(const FrameSyncConfig& c) const {
    return std::make_unique<Sync>(int(topics_.size()), c.policy, c.max_interval, std::size_t(c.queue_size),
                                  c.time_reset_threshold);
  }

  // The run-time parameters of FrameSyncConfig::params(), each against its
  // declaration (a refused value keeps the running ones and reports them
  // back); the sync is rebuilt, its open sets counted as dropped.
  void onReconfigure(SyncReconfigure& c) {
    dynamic_reconfigure::Config values;
    c.__toMessage__(values);
    std::lock_guard<std::mutex> lock(mutex_);
    std::string error;
    const std::optional<FrameSyncConfig> next = reconfigured(FrameSyncConfig::params(), cfg_, values, error);
    if (!next) {
      keepRunningValues(c, std::make_pair(std::cref(FrameSyncConfig::params()), cfg_));
      monitor_->error("sync parameters refused: " + error);
      NODELET_ERROR("sync parameters refused, running values kept: %s", error.c_str());
      return;
    }
    try {
      auto sync = makeSync(*next);
      for (std::size_t i = 0; i < sync_->open(); ++i) monitor_->dropped("open set (reconfigured)");
      sync_->finish();  // its open sets: counted as incomplete
      base_stats_ += sync_->stats();
      sync_ = std::move(sync);
      seen_ = {};
      cfg_ = *next;
      NODELET_INFO("frame sync: %s policy, max interval %.4f s, queue %d", toString(cfg_.policy).c_str(),
                   cfg_.max_interval, cfg_.queue_size);
    } catch (const std::exception& e) {
      monitor_->error(std::string("sync parameters rejected: ") + e.what());
      NODELET_ERROR("sync parameters rejected: %s", e.what());
    }
  }

  void updateSubscription() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    try {
      subscribeIfWanted();
    } catch (const std::exception& e) {  // e.g. an image_transport plugin that is not installed
      monitor_->error(std::string("subscribing: ") + e.what());
      NODELET_ERROR("cannot subscribe the camera topics (~image_transport '%s'): %s", transport_.c_str(), e.what());
      subs_.clear();
    }
  }

  void subscribeIfWanted() {
    const bool wanted = pub_.getNumSubscribers() > 0;
    if (wanted && subs_.empty() && compressed_subs_.empty()) {
      const bool decode_here = transport_ == "compressed" && !transportInstalled(transport_);
      for (size_t i = 0; i < topics_.size(); ++i) {
        if (decode_here) {
          compressed_subs_.push_back(getNodeHandle().subscribe<sensor_msgs::CompressedImage>(
              topics_[i] + "/compressed", 5,
              [this, i](const sensor_msgs::CompressedImageConstPtr& m) { onCompressedImage(m, int(i)); }));
          continue;
        }
        subs_.push_back(it_->subscribe(topics_[i], 5,
                                       boost::bind(&SyncNodelet::onImage, this, boost::placeholders::_1, int(i)),
                                       ros::VoidPtr(), image_transport::TransportHints(transport_)));
      }
      std::lock_guard<std::mutex> lock(mutex_);
      started_ = ros::Time::now();
    } else if (!wanted) {
      subs_.clear();
      compressed_subs_.clear();
    }
    monitor_->setInputExpected(wanted);
  }

  // Under sim time: a clock gone back behind the newest image resets the sync.
  void checkClock() {
    const std::int64_t now = simClockNs();
    if (!now) return;
    std::lock_guard<std::mutex> lock(mutex_);
    try {
      if (auto r = sync_->clockAt(now)) onTimeReset(*r);
      seen_ = sync_->stats();
    } catch (const std::exception& e) {
      monitor_->error(std::string("clock check: ") + e.what());
      NODELET_ERROR_THROTTLE(10.0, "clock check failed: %s", e.what());
    }
  }

  void onTimeReset(const Sync::TimeReset& r) {
    NODELET_WARN("frame sync: time went backwards from %s s to %s s: %s", formatStamp(r.from_ns).c_str(),
                 formatStamp(r.to_ns).c_str(), r.reason.c_str());
    monitor_->timeReset(formatStamp(r.from_ns) + " s -> " + formatStamp(r.to_ns) + " s: " + r.reason);
    // Arrival times are ROS time: after the clock went back they lie ahead.
    const ros::Time now = ros::Time::now();
    for (auto& c : cams_) {
      if (c.received) c.last_arrival = now;
    }
    started_ = now;
  }

  // Debian 12 packages no compressed image_transport plugin: with
  // ~image_transport compressed and no plugin, <topic>/compressed is read and
  // decoded here (cv::imdecode, grey) instead.
  bool transportInstalled(const std::string& transport) const {
    for (const auto& t : it_->getLoadableTransports()) {
      if (t == "image_transport/" + transport || t == transport) return true;
    }
    return false;
  }

  void onCompressedImage(const sensor_msgs::CompressedImageConstPtr& msg, int cam) {
    sensor_msgs::ImageConstPtr image;
    try {
      image = toImageMsg(msg->header, toGrey(*msg, topics_[cam] + "/compressed"));
    } catch (const std::exception& e) {
      monitor_->dropped("bad image");
      monitor_->error("image at " + formatStamp(std::int64_t(msg->header.stamp.toNSec())) + " from " + topics_[cam] +
                      "/compressed: " + e.what());
      NODELET_ERROR_THROTTLE(1.0, "%s/compressed: image at %.3f skipped: %s", topics_[cam].c_str(),
                             msg->header.stamp.toSec(), e.what());
      return;
    }
    onImage(image, cam);
  }

  void onImage(const sensor_msgs::ImageConstPtr& msg, int cam) {
    std::lock_guard<std::mutex> lock(mutex_);
    const double t0 = StageStats::now();
    try {
      addImage(msg, cam);
    } catch (const std::exception& e) {
      imageError(msg, cam, e.what());
    } catch (...) {
      imageError(msg, cam, "unknown exception");
    }
    monitor_->processed(StageStats::now() - t0);
  }

  void imageError(const sensor_msgs::ImageConstPtr& msg, int cam, const std::string& what) {
    monitor_->error("image at " + formatStamp(std::int64_t(msg->header.stamp.toNSec())) + " from " + topics_[cam] +
                    ": " + what);
    NODELET_ERROR_THROTTLE(1.0, "%s: image at %.3f skipped: %s", topics_[cam].c_str(), msg->header.stamp.toSec(),
                           what.c_str());
  }

  // An image the calibration does not describe, by its reason (nullopt: good).
  std::optional<std::string> badImage(const sensor_msgs::Image& msg, int cam) const {
    try {
      checkCameraImage(msg, topics_[cam]);
    } catch (const ImageConversionError& e) {
      return std::string(e.what());
    }
    const auto& model = rig_->cameras[cam].model;
    if (int(msg.width) != model.width() || int(msg.height) != model.height()) {
      return "image " + std::to_string(msg.width) + "x" + std::to_string(msg.height) + " " + msg.encoding +
             ": the calibration says " + std::to_string(model.width()) + "x" + std::to_string(model.height());
    }
    return std::nullopt;
  }

  void addImage(const sensor_msgs::ImageConstPtr& msg, int cam) {
    auto& c = cams_[cam];
    c.received++;
    c.last_arrival = ros::Time::now();
    c.stats->input();
    monitor_->input();
    if (!rig_) {
      monitor_->dropped("no rig yet (camera_info / tf)");
      return;
    }
    if (const auto bad = badImage(*msg, cam)) {
      ++c.bad;
      monitor_->dropped("bad image");
      NODELET_ERROR_THROTTLE(2.0, "%s (%s): %s; dropped", rig_->cameras[cam].name.c_str(), topics_[cam].c_str(),
                             bad->c_str());
      return;
    }
    auto sets = sync_->add(cam, std::int64_t(msg->header.stamp.toNSec()), msg);
    if (sync_->stats().time_resets != seen_.time_resets && sync_->lastTimeReset()) onTimeReset(*sync_->lastTimeReset());
    countDrops();
    for (auto& images : sets) publish(images);
  }

  // The sync's counters since the last image, as drops by reason.
  void countDrops() {
    const Sync::Stats& s = sync_->stats();
    for (auto n = seen_.dropped_incomplete; n < s.dropped_incomplete; ++n) monitor_->dropped("incomplete set");
    for (auto n = seen_.dropped_out_of_order; n < s.dropped_out_of_order; ++n) monitor_->dropped("out-of-order image");
    for (auto n = seen_.dropped_stale; n < s.dropped_stale; ++n) monitor_->dropped("stale image (old timeline)");
    seen_ = s;
  }

  void publish(const std::vector<sensor_msgs::ImageConstPtr>& images) {
    CameraFrameSetPtr out(new CameraFrameSet);
    out->header = images[0]->header;
    if (out->header.frame_id.empty()) out->header.frame_id = rig_->cameras[0].frame_id;
    for (size_t i = 0; i < images.size(); ++i) {
      out->camera_names.push_back(rig_->cameras[i].name);
      out->images.push_back(*images[i]);
      out->camera_infos.push_back(toCameraInfo(rig_->cameras[i], images[i]->header.stamp));
    }
    latency_sum_ += (ros::Time::now() - out->header.stamp).toSec();
    pub_.publish(out);
    monitor_->output();
  }

  // The sync's own values after StageMonitor's; runs on the reporting thread.
  void report(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    std::lock_guard<std::mutex> lock(mutex_);
    const ros::Time ros_now = ros::Time::now();  // sim time when a bag plays the clock
    if (started_.isZero()) started_ = ros_now;    // no clock yet when the subscription started
    stat.add("rig source", rig_source_ + (rig_ ? "" : " (waiting for camera_info / tf)"));
    std::string silent;
    for (size_t i = 0; i < cams_.size(); ++i) {
      const auto& c = cams_[i];
      const std::string name = cameraName(i);
      stat.addf(name + " rate (Hz)", "%.2f", c.stats->snapshot().input.rate_hz);
      const ros::Time since = c.received ? c.last_arrival : started_;
      if ((!subs_.empty() || !compressed_subs_.empty()) && !since.isZero() && (ros_now - since).toSec() > cfg_.silent_warning)
        silent += " " + name + "(" + topics_[i] + ")";
      if (c.bad) stat.add(name + " bad images", c.bad);
    }
    Sync::Stats s = base_stats_;
    s += sync_->stats();
    stat.add("frame sets out", s.complete);
    // Every frame set by what became of it: out + these = the frame sets seen.
    stat.add("frame sets dropped", s.setsDropped());
    stat.add("frame sets dropped: stamps backwards", s.sets_backwards);
    stat.add("frame sets dropped: duplicate stamp", s.sets_duplicate);
    stat.add("frame sets dropped: incomplete", s.dropped_incomplete);
    stat.add("frame sets dropped: old timeline", s.sets_stale);
    stat.add("incomplete sets dropped", s.dropped_incomplete);
    stat.add("out-of-order images dropped", s.dropped_out_of_order);
    stat.add("stale images dropped (old timeline)", s.dropped_stale);
    stat.addf("mean latency (s)", "%.3f", s.complete ? latency_sum_ / s.complete : 0.0);
    if (!silent.empty()) {
      stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::ERROR, "no images from" + silent);
      NODELET_WARN_THROTTLE(10.0, "no images for more than %.1f s from:%s", cfg_.silent_warning, silent.c_str());
    }
  }

  std::string cameraName(size_t i) const { return rig_ ? rig_->cameras[i].name : "cam" + std::to_string(i); }

  struct CamStats {
    std::uint64_t received = 0, bad = 0;
    ros::Time last_arrival;
    std::unique_ptr<StageStats> stats;  // this camera's input rate
  };
  FrameSyncConfig cfg_;
  FrameSyncNodeOptions opts_;
  std::string rig_source_, base_frame_;
  std::optional<Rig> rig_;  // set once (camchain: at start; camera_info: when all arrived)
  std::vector<std::string> topics_;
  std::string transport_;
  std::unique_ptr<Sync> sync_;
  Sync::Stats base_stats_, seen_;  // of the syncs before the last reconfigure; of sync_ at the last image
  std::vector<CamStats> cams_;
  std::vector<sensor_msgs::CameraInfoConstPtr> infos_;
  std::vector<ros::Subscriber> info_subs_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  std::vector<image_transport::Subscriber> subs_;
  std::vector<ros::Subscriber> compressed_subs_;  // decoded here: no compressed plugin installed
  ros::Publisher pub_;
  std::unique_ptr<StageMonitor> monitor_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<SyncReconfigure>> reconfigure_;
  ros::WallTimer clock_timer_, rig_timer_;
  ros::Time started_;
  double latency_sum_ = 0;
  std::mutex mutex_, connect_mutex_;
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::SyncNodelet, nodelet::Nodelet)
