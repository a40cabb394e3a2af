// Object detector nodelet: the core Detector (cv::dnn, YOLO family / NanoDet)
// on one camera's images.
//
// Topics are relative to the node's namespace (vehicle.launch: /fisheye_mapping).
// Subscribes  image (sensor_msgs/Image: a camera-image encoding of
//             ros/conversions.h, e.g. mono8 / bgr8 / rgb8 / bgra8 / rgba8,
//             through image_transport; ~image_transport selects the transport),
//             only while someone listens to an output (lazy).
// Publishes   detections       (fisheye_mapping/Detection2DArray) stamped with the
//                               IMAGE's header (stamp and frame_id), not now()
//             detections/image (bgr8, boxes drawn, through image_transport)
//                               while ~publish_annotated is true
// Parameters  ~model_config (model YAML, see config/detector/), ~dnn_backend
//             (opencv | default), ~dnn_target (cpu | opencl | opencl_fp16),
//             ~only_moving (true: publish the model's moving classes only),
//             ~publish_annotated, ~score_threshold / ~nms_threshold (override
//             the YAML's), ~image_transport.
// dynamic_reconfigure (cfg/DetectorReconfigure.cfg): score_threshold, nms_threshold,
// only_moving, publish_annotated, read through DetectorStageConfig::fromParams;
// the server starts from the effective thresholds (the model YAML's unless
// overridden), which it puts on the parameter server.
// A model that cannot be loaded is reported and the nodelet keeps running
// (publishing nothing, no reconfigure server); bad images and any exception in
// a callback are logged with the image stamp, counted and skipped.
// /diagnostics (StageMonitor, task "detector"): image rates, detection sets
// out, inference time per image, drops ("bad image", "no model"), callback
// errors, the thresholds in use; ERROR without a model. Stateless in time:
// nothing to reset when time goes backwards.
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <mutex>

#include <boost/thread/recursive_mutex.hpp>
#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include "fisheye_mapping/DetectorReconfigureConfig.h"

#include "fisheye_mapping/Detection2DArray.h"
#include "fisheye_mapping/core/detection/detector.h"
#include "fisheye_mapping/core/common/stream_timeline.h"
#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/node_options.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_monitor.h"

namespace fisheye_mapping {

namespace {

using ReconfigureConfig = DetectorReconfigureConfig;

// A float threshold as the decimal it was written as (0.3f -> 0.3, not
// 0.30000001192...), for the parameter server.
double decimal(float v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return std::atof(buf);
}

}  // namespace

class DetectorNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    monitor_ = std::make_unique<StageMonitor>(nh, pnh, "detector");
    monitor_->setExtraReport([this](diagnostic_updater::DiagnosticStatusWrapper& stat) { report(stat); });
    monitor_->setInputExpected(false);
    loadModel(pnh);
    if (detector_) startReconfigure(pnh);
    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    auto connect = [this](const ros::SingleSubscriberPublisher&) { updateSubscription(); };
    auto iconnect = [this](const image_transport::SingleSubscriberPublisher&) { updateSubscription(); };
    det_pub_ = nh.advertise<Detection2DArray>("detections", 5, connect, connect);
    // Advertised always: publish_annotated may be switched on at run time.
    image_pub_ = it_->advertise("detections/image", 2, iconnect, iconnect);
  }

  void loadModel(const ros::NodeHandle& pnh) {
    try {
      // Every detector parameter is declared once, in the core
      // (DetectorStageConfig); the node's own in DetectorNodeOptions. A bad
      // one leaves the stage without a model (ERROR on /diagnostics).
      requireKnownParams(pnh, {DetectorStageConfig::params().names(), DetectorNodeOptions::params().names()});
      transport_ = DetectorNodeOptions::params().read(RosParams(pnh), DetectorNodeOptions()).image_transport;
      stage_ = DetectorStageConfig::fromParams(RosParams(pnh));
      const DetectorModelConfig cfg = stage_.loadModel();
      const DnnDevice device = stage_.device();
      detector_ = std::make_unique<Detector>(cfg, device);
      // The thresholds in effect (the model YAML's unless overridden) are the running ones.
      stage_.score_threshold = cfg.score_threshold;
      stage_.nms_threshold = cfg.nms_threshold;
      NODELET_INFO("detector: %s head, %dx%d input, %zu classes, score %.3g nms %.3g, backend %s target %s, model %s",
                   headName(cfg.head), cfg.input_width, cfg.input_height, cfg.class_names.size(), cfg.score_threshold,
                   cfg.nms_threshold, device.backend.c_str(), device.target.c_str(), cfg.model_path.c_str());
    } catch (const std::exception& e) {
      load_error_ = e.what();
      NODELET_ERROR("detector has no model and will publish nothing: %s", e.what());
    }
  }

  // The thresholds in effect (the model YAML's unless ~score_threshold /
  // ~nms_threshold override them) go onto the parameter server first: the
  // server starts from the parameter server's values, and would otherwise
  // override the model's thresholds with the .cfg defaults.
  void startReconfigure(ros::NodeHandle& pnh) {
    pnh.setParam("score_threshold", decimal(detector_->config().score_threshold));
    pnh.setParam("nms_threshold", decimal(detector_->config().nms_threshold));
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<ReconfigureConfig>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](ReconfigureConfig& c, uint32_t) { onReconfigure(c); });
  }

  // The run-time parameters of DetectorStageConfig::params(), each against its
  // declaration (cfg/DetectorReconfigure.cfg is checked against them by
  // test_param_declarations). A refused value leaves the running ones, which
  // go back to the caller.
  void onReconfigure(ReconfigureConfig& c) {
    dynamic_reconfigure::Config values;
    c.__toMessage__(values);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      std::string error;
      const std::optional<DetectorStageConfig> next = reconfigured(DetectorStageConfig::params(), stage_, values, error);
      if (next) {
        detector_->setThresholds(*next->score_threshold, *next->nms_threshold);
        stage_ = *next;
        NODELET_INFO("detector reconfigured: score %.3g nms %.3g, only moving %d, annotated %d",
                     *stage_.score_threshold, *stage_.nms_threshold, int(stage_.only_moving),
                     int(stage_.publish_annotated));
      } else {
        monitor_->error("parameters refused: " + error);
        NODELET_ERROR("detector parameters refused, keeping the running ones: %s", error.c_str());
        keepRunningValues(c, std::make_pair(std::cref(DetectorStageConfig::params()), stage_));
      }
    }
    if (it_) updateSubscription();  // publish_annotated decides whether detections/image counts
  }

  // The stage's own values after StageMonitor's standard ones.
  void report(diagnostic_updater::DiagnosticStatusWrapper& stat) {
    if (!detector_) {
      stat.mergeSummary(diagnostic_msgs::DiagnosticStatus::ERROR, "no model: " + load_error_);
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    stat.addf("score threshold", "%.3g", detector_->config().score_threshold);
    stat.addf("nms threshold", "%.3g", detector_->config().nms_threshold);
    stat.add("only moving classes", stage_.only_moving);
    stat.add("publish annotated", stage_.publish_annotated);
  }

  void updateSubscription() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    try {
      subscribeIfWanted();
    } catch (const std::exception& e) {  // e.g. an image_transport plugin that is not installed
      monitor_->error(std::string("subscribing: ") + e.what());
      NODELET_ERROR("cannot subscribe the image (~image_transport '%s'): %s", transport_.c_str(), e.what());
    }
  }

  bool annotating() {
    std::lock_guard<std::mutex> lock(mutex_);
    return stage_.publish_annotated;
  }

  void subscribeIfWanted() {
    const bool wanted = det_pub_.getNumSubscribers() > 0 || (annotating() && image_pub_.getNumSubscribers() > 0);
    if (wanted && !sub_) {
      sub_ = it_->subscribe("image", 2, &DetectorNodelet::onImage, this, image_transport::TransportHints(transport_));
    } else if (!wanted && sub_) {
      sub_.shutdown();
    }
    monitor_->setInputExpected(wanted);
  }

  void onImage(const sensor_msgs::ImageConstPtr& msg) {
    monitor_->input();
    std::lock_guard<std::mutex> lock(mutex_);
    if (!detector_) {
      monitor_->dropped("no model");
      NODELET_ERROR_THROTTLE(5.0, "image at %.3f not processed: no model (%s)", msg->header.stamp.toSec(),
                             load_error_.c_str());
      return;
    }
    cv::Mat image;
    try {
      image = toCvImageShare(msg, ImageTarget::kDetector, getNodeHandle().resolveName("image"));
    } catch (const ImageConversionError& e) {  // the sender's fault: counted as a drop, not a stage error
      monitor_->dropped("bad image");
      NODELET_ERROR_THROTTLE(1.0, "image at %.3f skipped: %s", msg->header.stamp.toSec(), e.what());
      return;
    }
    try {
      detect(msg->header, image);
    } catch (const std::exception& ex) {
      monitor_->error("image at " + formatStamp(std::int64_t(msg->header.stamp.toNSec())) + ": " + ex.what());
      NODELET_ERROR_THROTTLE(1.0, "image at %.3f (%ux%u) skipped: %s", msg->header.stamp.toSec(), msg->width,
                             msg->height, ex.what());
    } catch (...) {
      monitor_->error("image at " + formatStamp(std::int64_t(msg->header.stamp.toNSec())) + ": unknown exception");
      NODELET_ERROR_THROTTLE(1.0, "image at %.3f (%ux%u) skipped: unknown exception", msg->header.stamp.toSec(),
                             msg->width, msg->height);
    }
  }

  // Called with mutex_ held. Detections are stamped with the image's stamp and frame.
  void detect(const std_msgs::Header& header, const cv::Mat& image) {
    const double t0 = StageStats::now();
    const std::vector<Detection> dets = detector_->detect(image, stage_.only_moving);
    monitor_->processed(StageStats::now() - t0);  // inference (with pre- and post-processing)
    det_pub_.publish(toDetectionArrayMsg(header, image.cols, image.rows, dets));
    monitor_->output();
    if (stage_.publish_annotated && image_pub_.getNumSubscribers() > 0)
      image_pub_.publish(toImageMsg(header, annotateDetections(image, dets)));
  }

  std::unique_ptr<Detector> detector_;
  DetectorStageConfig stage_;  // the running parameters (thresholds: detector_'s)
  std::string load_error_, transport_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  image_transport::Subscriber sub_;
  image_transport::Publisher image_pub_;
  ros::Publisher det_pub_;
  std::mutex mutex_, connect_mutex_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<ReconfigureConfig>> reconfigure_;
  std::unique_ptr<StageMonitor> monitor_;  // last: its timer stops first
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::DetectorNodelet, nodelet::Nodelet)
