// TSDF fusion nodelet: fuses (masked) fisheye depth into the core TsdfMap.
//
// Subscribes  depth (sensor_msgs/Image 32FC1, range along the ray, NaN invalid)
//             through a tf2 MessageFilter, so a frame waits for its pose.
// Publishes   mesh  (visualization_msgs/MarkerArray: one TRIANGLE_LIST per map
//                    block, only blocks changed since the last publish)
//             cloud (sensor_msgs/PointCloud2: surface points, world frame)
// Services    ~save_mesh, ~save_cloud, ~save_map, ~load_map (FilePath),
//             ~clear_map (std_srvs/Trigger)
// Parameters  see README ("TSDF fusion nodelet").
#include <memory>
#include <mutex>
#include <unordered_map>
#include <unordered_set>

#include <cv_bridge/cv_bridge.h>
#include <message_filters/subscriber.h>
#include <nodelet/nodelet.h>
#include <pcl_conversions/pcl_conversions.h>
#include <pluginlib/class_list_macros.hpp>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/image_encodings.h>
#include <std_srvs/Trigger.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/message_filter.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/MarkerArray.h>

#include "fisheye_mapping/FilePath.h"
#include "fisheye_mapping/FrameDone.h"
#include "fisheye_mapping/core/tsdf_map.h"
#include "fisheye_mapping/core/tsdf_mesher.h"
#include "fisheye_mapping/ros/ros_params.h"

namespace fisheye_mapping {

class TsdfFusionNodelet : public nodelet::Nodelet {
 public:
  ~TsdfFusionNodelet() override {
    std::lock_guard<std::mutex> lock(mutex_);
    if (map_ && !save_on_shutdown_.empty()) {
      try {
        map_->save(save_on_shutdown_);
        NODELET_INFO("map saved to %s", save_on_shutdown_.c_str());
      } catch (const std::exception& e) {
        NODELET_ERROR("could not save the map on shutdown: %s", e.what());
      }
    }
  }

 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    pnh.param("world_frame", world_frame_, std::string("map"));
    pnh.param("base_frame", base_frame_, std::string("base_link"));
    pnh.param("save_map_on_shutdown", save_on_shutdown_, std::string());
    pnh.param("output_directory", output_dir_, std::string("/tmp"));
    double publish_period = 1.0;
    pnh.param("publish_period", publish_period, publish_period);
    int queue_size = 10;
    pnh.param("queue_size", queue_size, queue_size);
    TsdfConfig cfg;
    try {
      cfg = tsdfConfigFrom(RosParams(pnh));
      rig_ = loadRigFromParams(pnh);
      map_ = std::make_unique<TsdfMap>(cfg);
    } catch (const std::exception& e) {
      NODELET_ERROR("TSDF fusion not started: %s", e.what());
      return;
    }
    mesher_ = std::make_unique<TsdfMesher>(cfg.min_observations);

    tf_buffer_ = std::make_unique<tf2_ros::Buffer>(ros::Duration(30.0));
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
    depth_sub_.subscribe(nh, "depth", queue_size);
    tf_filter_ = std::make_unique<tf2_ros::MessageFilter<sensor_msgs::Image>>(depth_sub_, *tf_buffer_, world_frame_,
                                                                              queue_size, nh);
    tf_filter_->registerCallback(&TsdfFusionNodelet::onDepth, this);
    tf_filter_->registerFailureCallback([this](const sensor_msgs::ImageConstPtr& msg,
                                               tf2_ros::filter_failure_reasons::FilterFailureReason reason) {
      ++dropped_no_tf_;
      done(msg->header, "no transform from '" + msg->header.frame_id + "' to '" + world_frame_ + "'");
      NODELET_WARN_THROTTLE(5.0, "depth frame at %.3f (frame '%s') dropped: no transform to '%s' (%s); %zu so far",
                            msg->header.stamp.toSec(), msg->header.frame_id.c_str(), world_frame_.c_str(),
                            reason == tf2_ros::filter_failure_reasons::OutTheBack ? "too old for the tf buffer"
                                                                                  : "tf never arrived",
                            dropped_no_tf_);
    });
    // Only changed blocks go out on each update; a subscriber that connects
    // later (rviz started mid-drive) is first sent the whole mesh.
    mesh_pub_ = nh.advertise<visualization_msgs::MarkerArray>(
        "mesh", 16, [this](const ros::SingleSubscriberPublisher& pub) { pub.publish(fullMesh()); });
    cloud_pub_ = nh.advertise<sensor_msgs::PointCloud2>("cloud", 2, true);
    // One FrameDone per depth frame finished with (fused or skipped): the
    // paced bag player waits for it.
    done_pub_ = nh.advertise<fisheye_mapping::FrameDone>("fusion_done", 100);
    services_.push_back(pnh.advertiseService("save_mesh", &TsdfFusionNodelet::saveMesh, this));
    services_.push_back(pnh.advertiseService("save_cloud", &TsdfFusionNodelet::saveCloud, this));
    services_.push_back(pnh.advertiseService("save_map", &TsdfFusionNodelet::saveMap, this));
    services_.push_back(pnh.advertiseService("load_map", &TsdfFusionNodelet::loadMap, this));
    services_.push_back(pnh.advertiseService("clear_map", &TsdfFusionNodelet::clearMap, this));
    timer_ = nh.createWallTimer(ros::WallDuration(publish_period), [this](const ros::WallTimerEvent&) { publish(); });
    NODELET_INFO("TSDF fusion: voxel %.3f m, truncation %.3f m, local map %.0fx%.0fx%.0f m, %s integrator",
                 cfg.voxel_size, cfg.truncation(), cfg.local_map_size.x(), cfg.local_map_size.y(), cfg.local_map_size.z(),
                 cfg.integrator.c_str());
  }

  // Tells the paced player that this depth frame is finished with.
  void done(const std_msgs::Header& header, const std::string& skipped_because) {
    fisheye_mapping::FrameDone msg;
    msg.header = header;
    msg.fused = skipped_because.empty();
    msg.reason = skipped_because;
    done_pub_.publish(msg);
  }

  void onDepth(const sensor_msgs::ImageConstPtr& msg) {
    std::string skipped = "not fused";
    struct Ack {  // every path out of here acknowledges the frame
      TsdfFusionNodelet* self;
      const std_msgs::Header& header;
      std::string& why;
      ~Ack() { self->done(header, why); }
    } ack{this, msg->header, skipped};
    const int cam_index = cameraIndex(msg->header.frame_id);
    if (cam_index < 0) {
      skipped = "frame '" + msg->header.frame_id + "' is not a camera of the rig";
      NODELET_WARN_THROTTLE(5.0, "depth frame '%s' is not a camera of the rig; frame skipped", msg->header.frame_id.c_str());
      return;
    }
    if (msg->encoding != sensor_msgs::image_encodings::TYPE_32FC1) {
      skipped = "encoding '" + msg->encoding + "' is not 32FC1";
      NODELET_WARN_THROTTLE(5.0, "depth must be 32FC1 (metres of range along the ray), got '%s'; frame skipped",
                            msg->encoding.c_str());
      return;
    }
    if (!last_stamp_.isZero() && msg->header.stamp < last_stamp_) {
      skipped = "stamp older than the last fused frame (time went backwards)";
      NODELET_WARN("depth stamp %.3f is older than the last fused one (%.3f): time went backwards; frame skipped "
                   "(call ~clear_map after restarting a bag)",
                   msg->header.stamp.toSec(), last_stamp_.toSec());
      return;
    }
    Eigen::Isometry3d T_W_C, T_W_B;
    try {
      T_W_C = tf2::transformToEigen(tf_buffer_->lookupTransform(world_frame_, msg->header.frame_id, msg->header.stamp));
      T_W_B = tf2::transformToEigen(tf_buffer_->lookupTransform(world_frame_, base_frame_, msg->header.stamp));
    } catch (const tf2::TransformException& e) {
      skipped = std::string("no pose: ") + e.what();
      NODELET_WARN_THROTTLE(5.0, "no pose for the depth frame at %.3f: %s; frame skipped", msg->header.stamp.toSec(), e.what());
      return;
    }
    cv_bridge::CvImageConstPtr depth;
    try {
      depth = cv_bridge::toCvShare(msg);
    } catch (const cv_bridge::Exception& e) {
      skipped = std::string("unreadable depth image: ") + e.what();
      NODELET_WARN_THROTTLE(5.0, "cannot read the depth image: %s; frame skipped", e.what());
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    try {
      const auto stats = map_->integrate(depth->image, rig_.cameras[cam_index].model, T_W_C, T_W_B.translation());
      last_stamp_ = msg->header.stamp;
      ++frames_fused_;
      skipped.clear();
      NODELET_DEBUG("fused frame %.3f: %zu valid pixels, %zu blocks", msg->header.stamp.toSec(), stats.valid_pixels,
                    stats.blocks_touched);
    } catch (const std::invalid_argument& e) {
      skipped = e.what();
      NODELET_WARN_THROTTLE(5.0, "depth frame at %.3f skipped: %s", msg->header.stamp.toSec(), e.what());
    }
  }

  int cameraIndex(const std::string& frame) const {
    for (size_t i = 0; i < rig_.cameras.size(); ++i) {
      if (rig_.cameras[i].frame_id == frame) return static_cast<int>(i);
    }
    return -1;
  }

  void publish() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!map_) return;
    const std::vector<BlockIndex> changed = mesher_->update(*map_);
    if (changed.empty() && !cleared_) return;
    const ros::Time stamp = last_stamp_.isZero() ? ros::Time::now() : last_stamp_;
    visualization_msgs::MarkerArray markers;
    if (cleared_) {
      visualization_msgs::Marker del;
      del.header.frame_id = world_frame_;
      del.action = visualization_msgs::Marker::DELETEALL;
      markers.markers.push_back(del);
      cleared_ = false;
      marker_ids_.clear();
      shown_.clear();
    }
    // One marker per changed block, once: ADD where it has triangles, DELETE
    // only where an earlier ADD is on screen (rviz warns about deleting what
    // it never got).
    std::unordered_set<int> sent;
    for (const BlockIndex& b : changed) {
      visualization_msgs::Marker m = blockMarker(b, stamp);
      if (!sent.insert(m.id).second) continue;
      if (m.action == visualization_msgs::Marker::DELETE) {
        if (!shown_.erase(m.id)) continue;
      } else {
        shown_.insert(m.id);
      }
      markers.markers.push_back(std::move(m));
    }
    if (!markers.markers.empty()) mesh_pub_.publish(markers);
    sensor_msgs::PointCloud2 cloud;
    pcl::toROSMsg(mesher_->surfaceCloud(), cloud);
    cloud.header.frame_id = world_frame_;
    cloud.header.stamp = stamp;
    cloud_pub_.publish(cloud);
  }

  visualization_msgs::MarkerArray fullMesh() {
    std::lock_guard<std::mutex> lock(mutex_);
    visualization_msgs::MarkerArray markers;
    if (!mesher_) return markers;
    visualization_msgs::Marker del;
    del.header.frame_id = world_frame_;
    del.action = visualization_msgs::Marker::DELETEALL;
    markers.markers.push_back(del);
    const ros::Time stamp = last_stamp_.isZero() ? ros::Time::now() : last_stamp_;
    for (const auto& kv : mesher_->blocks()) {
      if (kv.second.triangles.empty()) continue;
      markers.markers.push_back(blockMarker(kv.first, stamp));
      shown_.insert(markers.markers.back().id);
    }
    return markers;
  }

  // A marker id per block, handed out in order on first use: unique (a hash
  // of the block index could collide and hide a block).
  int markerId(const BlockIndex& b) const {
    auto it = marker_ids_.find(b);
    if (it == marker_ids_.end()) it = marker_ids_.emplace(b, static_cast<int>(marker_ids_.size())).first;
    return it->second;
  }

  visualization_msgs::Marker blockMarker(const BlockIndex& b, const ros::Time& stamp) const {
    visualization_msgs::Marker m;
    m.header.frame_id = world_frame_;
    m.header.stamp = stamp;
    m.ns = "tsdf_mesh";
    m.id = markerId(b);
    m.pose.orientation.w = 1.0;
    m.scale.x = m.scale.y = m.scale.z = 1.0;
    const auto it = mesher_->blocks().find(b);
    if (it == mesher_->blocks().end() || it->second.triangles.empty()) {
      m.action = visualization_msgs::Marker::DELETE;
      return m;
    }
    m.type = visualization_msgs::Marker::TRIANGLE_LIST;
    m.action = visualization_msgs::Marker::ADD;
    m.color.a = 1.0;
    for (const auto& v : it->second.triangles) {
      geometry_msgs::Point p;
      p.x = v.x(), p.y = v.y(), p.z = v.z();
      m.points.push_back(p);
      // Colour by height: 0 m dark grey-blue to 6 m light.
      std_msgs::ColorRGBA c;
      const float h = std::min(1.0f, std::max(0.0f, v.z() / 6.0f));
      c.r = 0.3f + 0.6f * h, c.g = 0.35f + 0.5f * h, c.b = 0.5f + 0.3f * h, c.a = 1.0f;
      m.colors.push_back(c);
    }
    return m;
  }

  std::string pathOr(const std::string& requested, const std::string& name) const {
    return requested.empty() ? output_dir_ + "/" + name : requested;
  }

  template <typename Fn>
  bool run(fisheye_mapping::FilePath::Response& res, const std::string& path, const char* what, Fn fn) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!map_) {
      res.success = false;
      res.message = "the TSDF fusion did not start (see its error log)";
      return true;
    }
    try {
      fn(path);
      res.success = true;
      res.message = std::string(what) + " " + path + ": done";
      NODELET_INFO("%s", res.message.c_str());
    } catch (const std::exception& e) {
      res.success = false;
      res.message = e.what();
      NODELET_ERROR("%s %s failed: %s", what, path.c_str(), e.what());
    }
    return true;
  }

  bool saveMesh(fisheye_mapping::FilePath::Request& req, fisheye_mapping::FilePath::Response& res) {
    return run(res, pathOr(req.path, "mesh.ply"), "save mesh to", [this](const std::string& p) {
      mesher_->update(*map_);
      mesher_->saveMeshPly(p);
    });
  }
  bool saveCloud(fisheye_mapping::FilePath::Request& req, fisheye_mapping::FilePath::Response& res) {
    return run(res, pathOr(req.path, "cloud.pcd"), "save cloud to", [this](const std::string& p) {
      mesher_->update(*map_);
      mesher_->saveCloudPcd(p);
    });
  }
  bool saveMap(fisheye_mapping::FilePath::Request& req, fisheye_mapping::FilePath::Response& res) {
    return run(res, pathOr(req.path, "map.fmtsdf"), "save map to", [this](const std::string& p) { map_->save(p); });
  }
  bool loadMap(fisheye_mapping::FilePath::Request& req, fisheye_mapping::FilePath::Response& res) {
    return run(res, pathOr(req.path, "map.fmtsdf"), "load map from", [this](const std::string& p) {
      map_->load(p);
      mesher_->clear();
      cleared_ = true;
    });
  }
  bool clearMap(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!map_) return res.success = false, res.message = "the TSDF fusion did not start", true;
    map_->clear();
    mesher_->clear();
    last_stamp_ = ros::Time();
    cleared_ = true;
    res.success = true;
    res.message = "map cleared";
    return true;
  }

  std::mutex mutex_;
  Rig rig_;
  std::unique_ptr<TsdfMap> map_;
  std::unique_ptr<TsdfMesher> mesher_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  message_filters::Subscriber<sensor_msgs::Image> depth_sub_;
  std::unique_ptr<tf2_ros::MessageFilter<sensor_msgs::Image>> tf_filter_;
  ros::Publisher mesh_pub_, cloud_pub_, done_pub_;
  std::vector<ros::ServiceServer> services_;
  ros::WallTimer timer_;
  std::string world_frame_, base_frame_, save_on_shutdown_, output_dir_;
  ros::Time last_stamp_;
  size_t frames_fused_ = 0, dropped_no_tf_ = 0;
  bool cleared_ = false;
  mutable std::unordered_map<BlockIndex, int, BlockIndexHash> marker_ids_;  // block -> marker id
  std::unordered_set<int> shown_;  // marker ids added and not deleted since
};

}  // namespace fisheye_mapping

PLUGINLIB_EXPORT_CLASS(fisheye_mapping::TsdfFusionNodelet, nodelet::Nodelet)
