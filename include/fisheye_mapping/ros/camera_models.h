// The camera model of each frame id from its latest CameraInfo, for a stage
// whose rig comes from CameraInfo topics (~rig_source camera_info): a model
// is parsed again only when that frame's calibration changes.
#ifndef FISHEYE_MAPPING_ROS_CAMERA_MODELS_H_
#define FISHEYE_MAPPING_ROS_CAMERA_MODELS_H_

#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include <ros/time.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/common/ordered_wait.h"
#include "fisheye_mapping/ros/camera_info.h"

namespace fisheye_mapping {

// The one CameraInfo -> camera model cache of the ROS layer: the TSDF stage's
// models by frame id (ImagesWithModels) and the mask stage's camera of its
// depth maps (fitting()). Not thread-safe.
class CameraModelsByFrame {
 public:
  // Null when no good CameraInfo of `frame` has come.
  std::shared_ptr<const CameraModel> find(const std::string& frame) const {
    const auto it = models_.find(frame);
    return it == models_.end() ? nullptr : it->second.second;
  }
  bool contains(const std::string& frame) const { return models_.count(frame) > 0; }

  // True when the model of msg's frame is new or changed. A bad CameraInfo
  // throws fromCameraInfo's error (its calibration is not parsed again while
  // it repeats), and that frame has no model until a good one.
  bool update(const sensor_msgs::CameraInfo& msg) {
    const std::string& frame = msg.header.frame_id;
    const auto it = models_.find(frame);
    if (it != models_.end() && sameCalibration(it->second.first, msg)) return false;
    const auto bad = refused_.find(frame);
    if (bad != refused_.end() && sameCalibration(bad->second.first, msg)) throw CalibrationError(bad->second.second);
    try {
      models_[frame] = {msg, std::make_shared<const CameraModel>(fromCameraInfo(msg))};
      refused_.erase(frame);
    } catch (const std::exception& e) {
      models_.erase(frame);
      refused_[frame] = {msg, e.what()};
      throw;
    }
    return true;
  }

  // The model of `info` (after update()) when it describes images of width x
  // height, else null and *why: "no camera_info on <topic>", "camera_info WxH
  // does not fit the image", or "camera_info refused: <error>".
  std::shared_ptr<const CameraModel> fitting(const sensor_msgs::CameraInfoConstPtr& info, int width, int height,
                                             const std::string& topic, std::string* why) {
    if (!info) return *why = "no camera_info on " + topic, nullptr;
    if (int(info->width) != width || int(info->height) != height) {
      *why = "camera_info " + std::to_string(info->width) + "x" + std::to_string(info->height) +
             " does not fit the image (" + std::to_string(width) + "x" + std::to_string(height) + ")";
      return nullptr;
    }
    try {
      update(*info);
    } catch (const std::exception& e) {
      return *why = std::string("camera_info refused: ") + e.what(), nullptr;
    }
    return find(info->header.frame_id);
  }

 private:
  std::map<std::string, std::pair<sensor_msgs::CameraInfo, std::shared_ptr<const CameraModel>>> models_;
  std::map<std::string, std::pair<sensor_msgs::CameraInfo, std::string>> refused_;  // the last bad one, its error
};

// The images of a stage (the TSDF's depth frames) with the camera model of
// their frame id: the rig's camera (~rig_source camchain), or the latest
// CameraInfo's (camera_info). With CameraInfo, which the stage before
// publishes too and which may come after the first images, an image before
// its frame's first CameraInfo waits for it (OrderedWait: the last
// max_waiting, max_wait_s of wall time at most; then it goes on without a
// model), and images go on one at a time in the order they came.
class ImagesWithModels {
 public:
  using Image = sensor_msgs::ImageConstPtr;
  // Called for each image, in order, with its model (null: none).
  using Process = std::function<void(const Image&, const std::shared_ptr<const CameraModel>&)>;

  ImagesWithModels(bool from_camera_info, Rig rig, Process process, size_t max_waiting = 8, double max_wait_s = 2.0)
      : from_camera_info_(from_camera_info), rig_(std::move(rig)), process_(std::move(process)),
        waiting_(max_waiting, max_wait_s) {}

  void arrive(const Image& image) {
    std::lock_guard<std::mutex> order(order_mutex_);
    if (!from_camera_info_) return process_(image, rigModel(image->header.frame_id));
    processAll(locked([&] { return waiting_.arrive(image, image->header.frame_id, now(), known()); }));
  }

  // A CameraInfo: true when its frame's model is new or changed (the images
  // waiting for it go on). A bad one throws (fromCameraInfo's error), and its
  // frame has no model until a good one.
  bool update(const sensor_msgs::CameraInfo& info) {
    std::lock_guard<std::mutex> order(order_mutex_);
    bool changed = false;
    std::vector<Image> ready = locked([&] {
      changed = models_.update(info);
      return waiting_.release(known());
    });
    processAll(ready);
    return changed;
  }

  // On a timer: the images that waited too long go on (without a model).
  void expire() {
    std::lock_guard<std::mutex> order(order_mutex_);
    processAll(locked([&] { return waiting_.expire(now(), known()); }));
  }

  // Why an image of `frame` came without a model: {the drop reason the
  // diagnostics count, a description}; `info_topic` is where CameraInfo comes.
  std::pair<std::string, std::string> noModel(const std::string& frame, const std::string& info_topic) const {
    if (from_camera_info_) return {"no camera_info yet", "no camera_info for frame '" + frame + "' yet (on " + info_topic + ")"};
    return {"not a rig camera", "frame '" + frame + "' is not a camera of the rig"};
  }

  size_t waiting() {
    std::lock_guard<std::mutex> lock(mutex_);
    return waiting_.size();
  }

 private:
  static double now() { return ros::WallTime::now().toSec(); }
  template <typename Fn>
  std::vector<Image> locked(Fn fn) {
    std::lock_guard<std::mutex> lock(mutex_);
    return fn();
  }
  OrderedWait<Image>::Known known() const {  // mutex_ held
    return [this](const std::string& frame) { return models_.contains(frame); };
  }
  std::shared_ptr<const CameraModel> rigModel(const std::string& frame) const {
    for (const auto& cam : rig_.cameras) {
      if (cam.frame_id == frame) return std::shared_ptr<const CameraModel>(std::shared_ptr<void>(), &cam.model);
    }
    return nullptr;
  }
  void processAll(const std::vector<Image>& images) {  // order_mutex_ held
    for (const Image& image : images) {
      std::shared_ptr<const CameraModel> model;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        model = models_.find(image->header.frame_id);
      }
      process_(image, model);
    }
  }

  const bool from_camera_info_;
  const Rig rig_;
  Process process_;
  std::mutex order_mutex_;  // taken first: one image at a time, in the order they came
  std::mutex mutex_;        // models_, waiting_
  CameraModelsByFrame models_;
  OrderedWait<Image> waiting_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_CAMERA_MODELS_H_
