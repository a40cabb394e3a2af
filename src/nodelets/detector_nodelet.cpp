// Object detector nodelet: the core Detector (cv::dnn, YOLO family / NanoDet)
// on one camera's images.
//
// Subscribes  image (sensor_msgs/Image: a camera-image encoding of
//             ros/conversions.h, e.g. mono8 / bgr8 / rgb8 / bgra8 / rgba8,
//             through image_transport; ~image_transport selects the transport),
//             only while someone listens to an output (lazy).
// Publishes   detections       (fisheye_mapping/Detection2DArray) stamped with the
//                               IMAGE's header (stamp and frame_id), not now()
//             detections_image (sensor_msgs/Image bgr8, boxes drawn) when
//                               ~publish_annotated is true
// Parameters  ~model_config (model YAML, see config/detector/), ~dnn_backend
//             (opencv | default), ~dnn_target (cpu | opencl | opencl_fp16),
//             ~only_moving (true: publish the model's moving classes only),
//             ~score_threshold / ~nms_threshold (override the YAML's).
// A model that cannot be loaded is reported and the nodelet keeps running
// (publishing nothing); bad images and any exception in a callback are
// logged with the image stamp, counted and skipped.
// /diagnostics: images in, detection sets out, errors (WARN for a while after
// one; ERROR without a model). Stateless in time: nothing to reset when time
// goes backwards.
#include <memory>
#include <mutex>

#include <atomic>

#include <diagnostic_updater/diagnostic_updater.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/core/detection/detector.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_health.h"

namespace fisheye_mapping {

class DetectorNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    pnh.param<std::string>("image_transport", transport_, "raw");
    try {
      // Every detector parameter is declared once, in the core (DetectorStageConfig).
      const DetectorStageConfig stage = DetectorStageConfig::fromParams(RosParams(pnh));
      only_moving_ = stage.only_moving;
      publish_annotated_ = stage.publish_annotated;
      const DetectorConfig cfg = stage.loadModel();
      const DnnDevice device = stage.device();
      detector_ = std::make_unique<Detector>(cfg, device);
      NODELET_INFO("detector: %s head, %dx%d input, %zu classes, backend %s target %s, model %s",
                   headName(cfg.head), cfg.input_width, cfg.input_height, cfg.class_names.size(),
                   device.backend.c_str(), device.target.c_str(), cfg.model_path.c_str());
    } catch (const std::exception& e) {
      load_error_ = e.what();
      NODELET_ERROR("detector has no model and will publish nothing: %s", e.what());
    }
    diag_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, getName());
    diag_->setHardwareID("detector");
    diag_->add("detections", this, &DetectorNodelet::diagnose);
    diag_timer_ = nh.createWallTimer(ros::WallDuration(1.0), [this](const ros::WallTimerEvent&) {
      try {
        diag_->force_update();
      } catch (const std::exception& e) {
        health_.error(std::string("diagnostics: ") + e.what());
      }
    });
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    auto connect = [this](const ros::SingleSubscriberPublisher&) { updateSubscription(); };
    det_pub_ = nh.advertise<Detection2DArray>("detections", 5, connect, connect);
    if (publish_annotated_) {
      auto iconnect = [this](const image_transport::SingleSubscriberPublisher&) { updateSubscription(); };
      image_pub_ = it_->advertise("detections_image", 2, iconnect, iconnect);
    }
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    if (detector_) {
      stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "detecting");
    } else {
      stat.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "no model: " + load_error_);
    }
    stat.add("images in", images_in_.load());
    stat.add("detection sets out", sets_out_.load());
    health_.report(stat);
  }

  void updateSubscription() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    try {
      subscribeIfWanted();
    } catch (const std::exception& e) {  // e.g. an image_transport plugin that is not installed
      health_.error(std::string("subscribing: ") + e.what());
      NODELET_ERROR("cannot subscribe the image (~image_transport '%s'): %s", transport_.c_str(), e.what());
    }
  }

  void subscribeIfWanted() {
    const bool wanted = det_pub_.getNumSubscribers() > 0 || (publish_annotated_ && image_pub_.getNumSubscribers() > 0);
    if (wanted && !sub_) {
      sub_ = it_->subscribe("image", 2, &DetectorNodelet::onImage, this, image_transport::TransportHints(transport_));
    } else if (!wanted && sub_) {
      sub_.shutdown();
    }
  }

  void onImage(const sensor_msgs::ImageConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    ++images_in_;
    if (!detector_) {
      NODELET_ERROR_THROTTLE(5.0, "image at %.3f not processed: no model (%s)", msg->header.stamp.toSec(),
                             load_error_.c_str());
      return;
    }
    try {
      const cv::Mat image = toCvImageShare(msg, ImageTarget::kDetector, getNodeHandle().resolveName("image"));
      const ros::WallTime t0 = ros::WallTime::now();
      const std::vector<Detection> dets = detector_->detect(image, only_moving_);
      NODELET_DEBUG("%zu detections in %.1f ms", dets.size(), (ros::WallTime::now() - t0).toSec() * 1e3);
      // Stamped with the image's stamp and frame.
      det_pub_.publish(toDetectionArrayMsg(msg->header, image.cols, image.rows, dets));
      ++sets_out_;
      if (publish_annotated_ && image_pub_.getNumSubscribers() > 0)
        image_pub_.publish(toImageMsg(msg->header, annotateDetections(image, dets)));
    } catch (const std::exception& ex) {
      health_.error("image at " + formatStamp(std::int64_t(msg->header.stamp.toNSec())) + ": " + ex.what());
      NODELET_ERROR_THROTTLE(1.0, "image at %.3f (%ux%u) skipped: %s", msg->header.stamp.toSec(), msg->width,
                             msg->height, ex.what());
    } catch (...) {
      health_.error("image at " + formatStamp(std::int64_t(msg->header.stamp.toNSec())) + ": unknown exception");
      NODELET_ERROR_THROTTLE(1.0, "image at %.3f (%ux%u) skipped: unknown exception", msg->header.stamp.toSec(),
                             msg->width, msg->height);
    }
  }

  std::unique_ptr<Detector> detector_;
  std::string load_error_, transport_;
  bool only_moving_ = true, publish_annotated_ = true;
  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::Subscriber sub_;
  image_transport::Publisher image_pub_;
  ros::Publisher det_pub_;
  std::mutex mutex_, connect_mutex_;
  StageHealth health_;
  std::unique_ptr<diagnostic_updater::Updater> diag_;
  ros::WallTimer diag_timer_;
  std::atomic<std::uint64_t> images_in_{0}, sets_out_{0};
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::DetectorNodelet, nodelet::Nodelet)
