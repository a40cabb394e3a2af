// Plane-sweep depth nodelet: the core PlaneSweep over synchronized frame sets.
//
// Subscribes  frames (fisheye_mapping/CameraFrameSet), only while someone
//             listens to an output (lazy, as stereo_image_proc)
// Publishes   depth      (sensor_msgs/Image 32FC1: metres of Euclidean range
//                         along the pixel's ray, NaN invalid)
//             cost       (32FC1: best matching cost (1 - ZNCC) / 2, NaN none)
//             uniqueness (32FC1: best / second-best cost; ~publish_uniqueness)
//             all with the reference camera image's header (stamp, frame_id).
// Parameters  ~camchain, ~mount (rig), ~reference_camera (cam0),
//             ~support_cameras (list; default all others), ~self_masks
//             (dict camera -> mask image path, non-zero = car body),
//             plane-sweep parameters (see config/plane_sweep_depth.yaml);
//             filter thresholds also through dynamic_reconfigure.
#include <memory>
#include <mutex>

#include <cv_bridge/cv_bridge.h>
#include <dynamic_reconfigure/server.h>
#include <nodelet/nodelet.h>
#include <opencv2/imgcodecs.hpp>
#include <pluginlib/class_list_macros.hpp>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>

#include "fisheye_mapping/CameraFrameSet.h"
#include "fisheye_mapping/PlaneSweepFiltersConfig.h"
#include "fisheye_mapping/core/plane_sweep.h"
#include "fisheye_mapping/ros/ros_params.h"

namespace fisheye_mapping {

namespace enc = sensor_msgs::image_encodings;

class PlaneSweepDepthNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    try {
      rig_ = loadRigFromParams(pnh);
      const PlaneSweepConfig config = loadPlaneSweepConfig(pnh);
      std::string ref_name = "cam0";
      pnh.param("reference_camera", ref_name, ref_name);
      ref_ = rig_.indexOf(ref_name);
      if (ref_ < 0) throw CalibrationError("~reference_camera: no camera '" + ref_name + "' in the rig");
      std::vector<std::string> support_names;
      if (!pnh.getParam("support_cameras", support_names)) {
        for (const auto& c : rig_.cameras) {
          if (c.name != ref_name) support_names.push_back(c.name);
        }
      }
      for (const auto& n : support_names) {
        const int i = rig_.indexOf(n);
        if (i < 0 || i == ref_) throw CalibrationError("~support_cameras: '" + n + "' is not a supporting camera of the rig");
        supports_.push_back(i);
      }
      std::map<std::string, std::string> masks;
      pnh.getParam("self_masks", masks);
      masks_.resize(rig_.cameras.size());
      for (const auto& [name, path] : masks) {
        const int i = rig_.indexOf(name);
        if (i < 0) throw CalibrationError("~self_masks: no camera '" + name + "' in the rig");
        masks_[i] = cv::imread(path, cv::IMREAD_GRAYSCALE);
        if (masks_[i].empty()) throw CalibrationError("~self_masks: cannot read " + path);
      }
      sweep_ = std::make_unique<PlaneSweep>(config);
      NODELET_INFO("plane sweep on %s, reference %s, %zu supporting camera(s), %s",
                   sweep_->backendName().c_str(), ref_name.c_str(), supports_.size(), config.resolution.c_str());
    } catch (const std::exception& e) {
      NODELET_FATAL("plane sweep depth not started: %s", e.what());
      return;
    }
    pnh.param("publish_uniqueness", publish_uniqueness_, false);
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<PlaneSweepFiltersConfig>>(reconfigure_mutex_, pnh);
    reconfigure_->setCallback([this](PlaneSweepFiltersConfig& c, uint32_t) { onReconfigure(c); });

    auto connect = [this](const ros::SingleSubscriberPublisher&) { updateSubscription(); };
    depth_pub_ = nh.advertise<sensor_msgs::Image>("depth", 2, connect, connect);
    cost_pub_ = nh.advertise<sensor_msgs::Image>("cost", 2, connect, connect);
    if (publish_uniqueness_) uniqueness_pub_ = nh.advertise<sensor_msgs::Image>("uniqueness", 2, connect, connect);
  }

  void onReconfigure(PlaneSweepFiltersConfig& c) {
    DepthFilterConfig f;
    f.texture = c.filter_texture;
    f.min_texture_snr = c.min_texture_snr;
    f.cost = c.filter_cost;
    f.alpha_upper = c.alpha_upper;
    f.alpha_lower = c.alpha_lower;
    f.split_row = c.split_row;
    f.uniqueness = c.filter_uniqueness;
    f.max_ratio = c.max_ratio;
    f.consistency = c.filter_consistency;
    c.consistency_window |= 1;  // odd windows only
    f.consistency_window = c.consistency_window;
    f.gamma = c.gamma;
    f.delta = c.delta;
    std::lock_guard<std::mutex> lock(mutex_);
    f.min_noise_std = sweep_->config().filters.min_noise_std;  // not reconfigurable
    try {
      sweep_->setFilters(f);
    } catch (const std::exception& e) {
      NODELET_ERROR("filter parameters rejected: %s", e.what());
    }
  }

  void updateSubscription() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    const bool wanted = depth_pub_.getNumSubscribers() > 0 || cost_pub_.getNumSubscribers() > 0 ||
                        (publish_uniqueness_ && uniqueness_pub_.getNumSubscribers() > 0);
    if (wanted && !sub_) {
      sub_ = getNodeHandle().subscribe("frames", 1, &PlaneSweepDepthNodelet::onFrames, this);
    } else if (!wanted && sub_) {
      sub_.shutdown();
    }
  }

  // Grey or colour image as the core takes it; throws naming the problem.
  static cv::Mat toCv(const sensor_msgs::ImageConstPtr& msg, const std::string& name) {
    const std::string& e = msg->encoding;
    if (e == enc::MONO8 || e == enc::MONO16 || e == enc::TYPE_32FC1) return cv_bridge::toCvShare(msg)->image;
    if (e == enc::BGR8 || e == enc::RGB8 || e == enc::BGRA8 || e == enc::RGBA8) {
      return cv_bridge::toCvShare(msg, enc::BGR8)->image;
    }
    throw std::invalid_argument(name + ": unsupported encoding '" + e + "' (mono8, mono16, 32FC1 or 8-bit colour)");
  }

  void onFrames(const CameraFrameSetConstPtr& set) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!sweep_) return;
    try {
      if (set->camera_names.size() != set->images.size()) {
        throw std::invalid_argument("frame set has " + std::to_string(set->camera_names.size()) + " names but " +
                                    std::to_string(set->images.size()) + " images");
      }
      auto find = [&](int cam) -> sensor_msgs::ImageConstPtr {
        for (size_t i = 0; i < set->camera_names.size(); ++i) {
          if (set->camera_names[i] == rig_.cameras[cam].name) {
            return sensor_msgs::ImageConstPtr(set, &set->images[i]);  // aliases the set's lifetime
          }
        }
        return nullptr;
      };
      const sensor_msgs::ImageConstPtr ref_img = find(ref_);
      if (!ref_img) throw std::invalid_argument("frame set has no image of the reference camera " + rig_.cameras[ref_].name);
      const SweepView ref = rigSweepView(rig_, ref_, ref_, toCv(ref_img, rig_.cameras[ref_].name), masks_[ref_]);
      std::vector<SweepView> views;
      for (int i : supports_) {
        const sensor_msgs::ImageConstPtr img = find(i);
        if (!img) {
          NODELET_WARN_THROTTLE(5.0, "frame set has no image of %s; sweeping without it", rig_.cameras[i].name.c_str());
          continue;
        }
        views.push_back(rigSweepView(rig_, i, ref_, toCv(img, rig_.cameras[i].name), masks_[i]));
      }
      const Eigen::Isometry3d T_base_ref = rig_.cameras[ref_].T_base_cam;
      const DepthResult r = sweep_->compute(ref, views, &T_base_ref);
      if (!r.dropped_views.empty()) NODELET_INFO_ONCE("supporting view dropped: %s", r.dropped_views.front().c_str());
      std_msgs::Header header = ref_img->header;
      if (header.frame_id.empty()) header.frame_id = rig_.cameras[ref_].frame_id;
      depth_pub_.publish(cv_bridge::CvImage(header, enc::TYPE_32FC1, r.depth).toImageMsg());
      cost_pub_.publish(cv_bridge::CvImage(header, enc::TYPE_32FC1, r.cost).toImageMsg());
      if (publish_uniqueness_) uniqueness_pub_.publish(cv_bridge::CvImage(header, enc::TYPE_32FC1, r.uniqueness).toImageMsg());
      NODELET_DEBUG("depth in %.1f ms (sweep %.1f, filters %.1f)", r.total_ms, r.sweep_ms, r.filter_ms);
    } catch (const std::exception& e) {
      NODELET_ERROR_THROTTLE(0.2, "frame set at %.3f skipped: %s", set->header.stamp.toSec(), e.what());
    }
  }

  Rig rig_;
  int ref_ = 0;
  std::vector<int> supports_;
  std::vector<cv::Mat> masks_;
  std::unique_ptr<PlaneSweep> sweep_;
  bool publish_uniqueness_ = false;
  std::mutex mutex_, connect_mutex_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<PlaneSweepFiltersConfig>> reconfigure_;
  ros::Subscriber sub_;
  ros::Publisher depth_pub_, cost_pub_, uniqueness_pub_;
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::PlaneSweepDepthNodelet, nodelet::Nodelet)
