#include "fisheye_mapping/ros/tsdf_topics.h"

#include <cmath>

#include <nav_msgs/OccupancyGrid.h>
#include <sensor_msgs/PointCloud2.h>
#include <visualization_msgs/MarkerArray.h>

#include "fisheye_mapping/FrameDone.h"

#include "fisheye_mapping/ros/conversions.h"
#include "fisheye_mapping/ros/tsdf_messages.h"

namespace fisheye_mapping {

TsdfTopics::TsdfTopics(ros::NodeHandle& nh, const std::string& world_frame, MeshColoring colour,
                       std::function<void(const ros::SingleSubscriberPublisher&)> on_mesh_connect)
    : frame_(world_frame), markers_(world_frame, colour) {
  mesh_ = nh.advertise<visualization_msgs::MarkerArray>("tsdf/mesh", 16, std::move(on_mesh_connect));
  cloud_ = nh.advertise<sensor_msgs::PointCloud2>(
      "tsdf/cloud", 2, [this](const ros::SingleSubscriberPublisher&) { cloud_subscriber_came_ = true; },
      ros::SubscriberStatusCallback(), ros::VoidConstPtr(), true);
  occupancy_ = nh.advertise<nav_msgs::OccupancyGrid>("tsdf/occupancy", 1, true);
  esdf_ = nh.advertise<sensor_msgs::PointCloud2>("tsdf/esdf", 1, true);
  done_ = nh.advertise<fisheye_mapping::FrameDone>("tsdf/fusion_done", 100);
}

ros::Time TsdfTopics::stamp(const TsdfFusionStage& stage) const {
  return stage.lastStamp() ? ros::Time().fromNSec(stage.lastStamp()) : ros::Time::now();
}

void TsdfTopics::publish(TsdfFusionStage& stage) {
  const bool mesh_wanted = mesh_.getNumSubscribers() > 0, cloud_wanted = cloud_.getNumSubscribers() > 0;
  if (!mesh_wanted && !cloud_wanted) return;  // a subscriber that comes gets everything (sendAll, cloud_subscriber_came_)
  const std::vector<BlockIndex> changed = stage.updateMesh();
  if (mesh_wanted) {
    const visualization_msgs::MarkerArray markers = markers_.update(stage.mesher().blocks(), changed, stamp(stage));
    if (!markers.markers.empty()) mesh_.publish(markers);
  } else {
    markers_.markChanged(changed);  // sent with the next update to a mesh subscriber
  }
  if (!cloud_wanted) return;
  const bool new_subscriber = cloud_subscriber_came_.exchange(false);
  if (!stage.takeCloudStale() && changed.empty() && !new_subscriber) return;
  cloud_.publish(toCloudMsg(stage.mesher().surfaceCloud(), frame_, stamp(stage)));
}

void TsdfTopics::publishReset(TsdfFusionStage& stage) {
  if (stage.takeMeshReset()) mesh_.publish(markers_.clear());
}

void TsdfTopics::sendAll(TsdfFusionStage& stage, const ros::SingleSubscriberPublisher& subscriber) {
  const visualization_msgs::MarkerArray pending =
      markers_.update(stage.mesher().blocks(), stage.updateMesh(), stamp(stage));
  if (!pending.markers.empty()) mesh_.publish(pending);
  subscriber.publish(markers_.republishAll(stage.mesher().blocks(), stamp(stage)));
}

void TsdfTopics::publishOccupancy(TsdfFusionStage& stage) {
  const bool grid_wanted = occupancy_.getNumSubscribers() > 0, esdf_wanted = esdf_.getNumSubscribers() > 0;
  if (!grid_wanted && !esdf_wanted) return;
  double z = 0;
  const std::optional<OccupancyGrid> grid = stage.occupancy(&z);
  if (!grid) return;
  const ros::Time stamp = ros::Time().fromNSec(stage.lastStamp());
  if (grid_wanted) occupancy_.publish(toOccupancyGridMsg(*grid, frame_, stamp, z));
  if (!esdf_wanted || grid->distance.empty()) return;
  // The distance field as voxblox's ESDF slice: a point per known cell on its
  // local ground (the vehicle's height where there is none), intensity = m.
  pcl::PointCloud<pcl::PointXYZI> cloud;
  for (int y = 0; y < grid->height; ++y)
    for (int x = 0; x < grid->width; ++x) {
      const size_t i = static_cast<size_t>(y) * grid->width + x;
      if (!std::isfinite(grid->distance[i])) continue;
      const Eigen::Vector2d c = grid->cellCenter(x, y);
      pcl::PointXYZI p;
      p.x = static_cast<float>(c.x());
      p.y = static_cast<float>(c.y());
      p.z = std::isfinite(grid->ground[i]) ? grid->ground[i] : static_cast<float>(z);
      p.intensity = grid->distance[i];
      cloud.push_back(p);
    }
  esdf_.publish(toCloudMsg(cloud, frame_, stamp));
}

void TsdfTopics::frameDone(const std_msgs::Header& header, const std::string& skipped_because) {
  fisheye_mapping::FrameDone msg;
  msg.header = header;
  msg.fused = skipped_because.empty();
  msg.reason = skipped_because;
  done_.publish(msg);
}

}  // namespace fisheye_mapping
