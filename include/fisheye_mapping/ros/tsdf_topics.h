// The TSDF stage's map outputs as topics (what the TSDF nodelet publishes
// from its core TsdfFusionStage):
//   tsdf/mesh       MarkerArray through MeshMarkerStream: only the blocks that
//                   changed; a subscriber that connects later first gets the
//                   whole mesh; one DELETEALL after a clear, load or reset;
//   tsdf/cloud      PointCloud2 (latched) of the surface, when blocks changed
//                   or after a reset, and for a subscriber that connects;
// The mesh and the cloud are built only while someone subscribes to one of
// them: a map nobody looks at costs no meshing, no cloud and no serialising
// each period (the store keeps the changed blocks for later).
//   tsdf/occupancy  OccupancyGrid (latched) around the vehicle's last fused
//                   pose, while someone subscribes;
//   tsdf/esdf       PointCloud2 (latched, x y z intensity) of the same grid's
//                   distance field: a point per known cell on its local
//                   ground, intensity the distance (m) to the nearest
//                   obstacle, while someone subscribes;
//   tsdf/fusion_done  FrameDone for each depth frame, fused or skipped.
// The caller holds the stage's lock around every call but the constructor
// and frameDone().
#ifndef FISHEYE_MAPPING_ROS_TSDF_TOPICS_H_
#define FISHEYE_MAPPING_ROS_TSDF_TOPICS_H_

#include <atomic>

#include <functional>
#include <string>
#include <vector>

#include <ros/node_handle.h>
#include <ros/single_subscriber_publisher.h>
#include <std_msgs/Header.h>

#include "fisheye_mapping/core/tsdf/fusion_stage.h"
#include "fisheye_mapping/ros/mesh_markers.h"

namespace fisheye_mapping {

class TsdfTopics {
 public:
  // `on_mesh_connect`: a subscriber connected to tsdf/mesh (the caller takes
  // its lock and calls sendAll); it may run before the constructor returns.
  TsdfTopics(ros::NodeHandle& nh, const std::string& world_frame, MeshColoring colour,
             std::function<void(const ros::SingleSubscriberPublisher&)> on_mesh_connect);

  // Every publish period, while someone subscribes: the mesh blocks that
  // changed, and the cloud.
  void publish(TsdfFusionStage& stage);
  // After a clear, load or reset of the stage's map: rviz gets a DELETEALL.
  void publishReset(TsdfFusionStage& stage);
  // A late subscriber: pending changes to everyone first, then the whole mesh to it.
  void sendAll(TsdfFusionStage& stage, const ros::SingleSubscriberPublisher& subscriber);
  // The obstacle grid and its distance field, when someone subscribes and
  // the stage has a pose.
  void publishOccupancy(TsdfFusionStage& stage);
  // tsdf/fusion_done: this depth frame is finished with (for the paced
  // player), fused or skipped because of `skipped_because` (non-empty).
  void frameDone(const std_msgs::Header& header, const std::string& skipped_because);
  // Blocks the stage re-meshed outside publish() (exports, a new min_observations).
  void markChanged(const std::vector<BlockIndex>& blocks) { markers_.markChanged(blocks); }
  size_t numShown() const { return markers_.numShown(); }

 private:
  ros::Time stamp(const TsdfFusionStage& stage) const;

  std::string frame_;
  MeshMarkerStream markers_;
  ros::Publisher mesh_, cloud_, occupancy_, esdf_, done_;
  std::atomic<bool> cloud_subscriber_came_{false};  // a new tsdf/cloud subscriber waits for its first cloud
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_TSDF_TOPICS_H_
