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
#include <algorithm>
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
#include "fisheye_mapping/SyncReconfigureConfig.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/core/sync/sync_report.h"
#include "fisheye_mapping/ros/camera_info.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/node_options.h"
#include "fisheye_mapping/ros/nodelet_glue.h"
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
    log_ = NodeletLogger(getName());
    try {
      // Every sync parameter is declared once, in the core (FrameSyncConfig);
      // the node's own in FrameSyncNodeOptions.
      requireKnownParams(pnh, {FrameSyncConfig::params().names(), FrameSyncNodeOptions::params().names()});
      cfg_ = FrameSyncConfig::fromParams(RosParams(pnh));
      opts_ = FrameSyncNodeOptions::params().read(RosParams(pnh), FrameSyncNodeOptions());
      topics_ = cfg_.image_topics;
      if (!opts_.rig.fromCameraInfo()) {
        rig_ = loadRigFromParams(pnh);
        topics_ = imageTopicsForRig(*rig_, topics_);
      } else {
        if (topics_.empty()) throw std::invalid_argument("~rig_source camera_info: set ~image_topics (camera order)");
        subscribeCameraInfos();
      }
      sync_ = makeSync(cfg_);
      monitor_ = std::make_unique<StageMonitor>(nh, pnh, "sync");
    } catch (const std::exception& e) {
      NODELET_FATAL("frame sync not started: %s", e.what());
      return;
    }
    cams_ = std::make_unique<CameraActivity>(int(topics_.size()), monitor_->options().window_s);
    monitor_->setExtraReport([this](diagnostic_updater::DiagnosticStatusWrapper& stat) { report(stat); });
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    input_ = std::make_unique<LazySubscription>(
        *monitor_, log_, "the camera topics (~image_transport '" + opts_.image_transport + "')",
        [this] { return pub_.getNumSubscribers() > 0; }, [this] { subscribeImages(); },
        [this] {
          subs_.clear();
          compressed_subs_.clear();
        });
    pub_ = nh.advertise<CameraFrameSet>("frames", 5, input_->rosCallback(), input_->rosCallback());
    // A subscriber that connected while the publisher was being assigned may
    // have run the connect callback too early (it saw none): look once more.
    input_->update();
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<SyncReconfigure>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](SyncReconfigure& c, uint32_t) { onReconfigure(c); });
    // Under sim time: a clock gone back behind the newest image resets the sync.
    clock_timer_ = simClockTimer(nh, [this](std::int64_t now) {
      std::lock_guard<std::mutex> lock(mutex_);
      guarded(*monitor_, log_, "clock check", ros::Time(), [&] {
        if (auto r = sync_->clockAt(now)) onTimeReset(*r);
        seen_ = sync_->stats();
      }, 10.0);
    });
    std::string list;
    for (const auto& t : topics_) list += " " + t;
    NODELET_INFO("frame sync: %zu cameras (rig from %s, %s policy, max interval %.4f s):%s", topics_.size(),
                 opts_.rig.rig_source.c_str(), toString(cfg_.policy).c_str(), cfg_.max_interval, list.c_str());
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
          info_topics[i], 1, [this, i](const sensor_msgs::CameraInfoConstPtr& m) {
            std::lock_guard<std::mutex> lock(mutex_);
            if (!infos_[i]) infos_[i] = m;
          }));
    }
    rig_timer_ = getNodeHandle().createWallTimer(ros::WallDuration(0.5), [this](const ros::WallTimerEvent&) { tryBuildRig(); });
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
      rig_ = rigFromCameraInfosAndTf(infos, {}, *tf_buffer_, opts_.base_frame, ros::Time(0), 0.0);
      NODELET_INFO("rig of %zu cameras built from their CameraInfo and tf (base frame %s)", infos.size(),
                   opts_.base_frame.c_str());
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
    std::lock_guard<std::mutex> lock(mutex_);
    const auto next = checkedReconfigure(c, FrameSyncConfig::params(), cfg_, *monitor_, log_, "sync parameters");
    if (!next) return;
    guarded(*monitor_, log_, "reconfigure", ros::Time(), [&] {
      auto sync = makeSync(*next);
      for (std::size_t i = 0; i < sync_->open(); ++i) monitor_->dropped("open set (reconfigured)");
      sync_->finish();  // its open sets: counted as incomplete
      base_stats_ += sync_->stats();
      sync_ = std::move(sync);
      seen_ = {};
      cfg_ = *next;
      NODELET_INFO("frame sync: %s policy, max interval %.4f s, queue %d", toString(cfg_.policy).c_str(),
                   cfg_.max_interval, cfg_.queue_size);
    });
  }

  // Debian 12 packages no compressed image_transport plugin: with
  // ~image_transport compressed and no plugin, <topic>/compressed is read and
  // decoded here (cv::imdecode, grey) instead.
  void subscribeImages() {
    bool plugin = false;
    for (const auto& t : it_->getLoadableTransports())
      plugin = plugin || t == "image_transport/" + opts_.image_transport || t == opts_.image_transport;
    const bool decode_here = opts_.image_transport == "compressed" && !plugin;
    for (size_t i = 0; i < topics_.size(); ++i) {
      if (decode_here) {
        compressed_subs_.push_back(getNodeHandle().subscribe<sensor_msgs::CompressedImage>(
            topics_[i] + "/compressed", 5,
            [this, i](const sensor_msgs::CompressedImageConstPtr& m) { onCompressedImage(m, int(i)); }));
        continue;
      }
      subs_.push_back(it_->subscribe(topics_[i], 5,
                                     boost::bind(&SyncNodelet::onImage, this, boost::placeholders::_1, int(i)),
                                     ros::VoidPtr(), image_transport::TransportHints(opts_.image_transport)));
    }
    std::lock_guard<std::mutex> lock(mutex_);
    cams_->listening(ros::Time::now().toSec());
  }

  void onTimeReset(const Sync::TimeReset& r) {
    noteTimeReset(*monitor_, log_, "frame sync", r.from_ns, r.to_ns, r.reason);
    // Arrival times are ROS time: after the clock went back they lie ahead.
    cams_->clockWentBack(ros::Time::now().toSec());
  }

  void onCompressedImage(const sensor_msgs::CompressedImageConstPtr& msg, int cam) {
    sensor_msgs::ImageConstPtr image;
    const bool ok = guarded(*monitor_, log_, "image from " + topics_[cam] + "/compressed", msg->header.stamp,
                            [&] { image = toImageMsg(msg->header, toGrey(*msg, topics_[cam] + "/compressed")); });
    if (!ok) {
      monitor_->dropped("bad image");
      return;
    }
    onImage(image, cam);
  }

  void onImage(const sensor_msgs::ImageConstPtr& msg, int cam) {
    std::lock_guard<std::mutex> lock(mutex_);
    const double t0 = StageStats::now();
    guarded(*monitor_, log_, "image from " + topics_[cam], msg->header.stamp, [&] { addImage(msg, cam); });
    monitor_->processed(StageStats::now() - t0);
  }

  // An image the calibration does not describe, by its reason (nullopt: good).
  std::optional<std::string> badImage(const sensor_msgs::Image& msg, int cam) const {
    try {
      checkCameraImage(msg, topics_[cam]);
    } catch (const ImageConversionError& e) {
      return std::string(e.what());
    }
    return imageSizeMismatch(int(msg.width), int(msg.height), msg.encoding, rig_->cameras[cam].model);
  }

  void addImage(const sensor_msgs::ImageConstPtr& msg, int cam) {
    cams_->arrived(cam, ros::Time::now().toSec());
    monitor_->input();
    if (!rig_) {
      monitor_->dropped("no rig yet (camera_info / tf)");
      return;
    }
    if (const auto bad = badImage(*msg, cam)) {
      cams_->bad(cam);
      monitor_->dropped("bad image");
      NODELET_ERROR_THROTTLE(2.0, "%s (%s): %s; dropped", rig_->cameras[cam].name.c_str(), topics_[cam].c_str(),
                             bad->c_str());
      return;
    }
    auto sets = sync_->add(cam, std::int64_t(msg->header.stamp.toNSec()), msg);
    if (sync_->stats().time_resets != seen_.time_resets && sync_->lastTimeReset()) onTimeReset(*sync_->lastTimeReset());
    for (const auto& reason : newSyncDrops(seen_, sync_->stats())) monitor_->dropped(reason);
    seen_ = sync_->stats();
    for (auto& images : sets) publish(images);
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
    const bool listening = input_->active();
    std::lock_guard<std::mutex> lock(mutex_);
    stat.add("rig source", opts_.rig.rig_source + (rig_ ? "" : " (waiting for camera_info / tf)"));
    const std::vector<int> quiet = cams_->silent(ros::Time::now().toSec(), cfg_.silent_warning);
    std::string silent;
    for (int i = 0; i < cams_->cameras(); ++i) {
      const std::string name = rig_ ? rig_->cameras[i].name : "cam" + std::to_string(i);
      stat.addf(name + " rate (Hz)", "%.2f", cams_->rateHz(i));
      if (listening && std::find(quiet.begin(), quiet.end(), i) != quiet.end()) silent += " " + name + "(" + topics_[i] + ")";
      if (cams_->badImages(i)) stat.add(name + " bad images", cams_->badImages(i));
    }
    Sync::Stats s = base_stats_;
    s += sync_->stats();
    for (const auto& kv : syncReportValues(s)) stat.add(kv.first, kv.second);
    stat.addf("mean latency (s)", "%.3f", s.complete ? latency_sum_ / s.complete : 0.0);
    if (!silent.empty()) {
      stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::ERROR, "no images from" + silent);
      NODELET_WARN_THROTTLE(10.0, "no images for more than %.1f s from:%s", cfg_.silent_warning, silent.c_str());
    }
  }

  FrameSyncConfig cfg_;
  FrameSyncNodeOptions opts_;
  NodeletLogger log_;
  std::optional<Rig> rig_;  // set once (camchain: at start; camera_info: when all arrived)
  std::vector<std::string> topics_;
  std::unique_ptr<Sync> sync_;
  Sync::Stats base_stats_, seen_;  // of the syncs before the last reconfigure; of sync_ at the last image
  std::unique_ptr<CameraActivity> cams_;
  std::vector<sensor_msgs::CameraInfoConstPtr> infos_;
  std::vector<ros::Subscriber> info_subs_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  std::vector<image_transport::Subscriber> subs_;
  std::vector<ros::Subscriber> compressed_subs_;  // decoded here: no compressed plugin installed
  ros::Publisher pub_;
  std::unique_ptr<StageMonitor> monitor_;
  std::unique_ptr<LazySubscription> input_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<SyncReconfigure>> reconfigure_;
  ros::WallTimer clock_timer_, rig_timer_;
  double latency_sum_ = 0;
  std::mutex mutex_;
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::SyncNodelet, nodelet::Nodelet)
