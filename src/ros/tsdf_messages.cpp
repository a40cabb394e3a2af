#include "fisheye_mapping/ros/tsdf_messages.h"

namespace fisheye_mapping {

nav_msgs::OccupancyGrid toOccupancyGridMsg(const OccupancyGrid& grid, const std::string& frame, const ros::Time& stamp,
                                           double z) {
  nav_msgs::OccupancyGrid msg;
  msg.header.frame_id = frame;
  msg.header.stamp = stamp;
  msg.info.map_load_time = stamp;
  msg.info.resolution = static_cast<float>(grid.resolution);
  msg.info.width = static_cast<uint32_t>(grid.width);
  msg.info.height = static_cast<uint32_t>(grid.height);
  msg.info.origin.position.x = grid.origin.x();
  msg.info.origin.position.y = grid.origin.y();
  msg.info.origin.position.z = z;
  msg.info.origin.orientation.w = 1.0;
  msg.data.assign(grid.cells.begin(), grid.cells.end());
  return msg;
}

std::vector<Eigen::AlignedBox3d> carveRegions(const TrackedVehicleArray& msg) {
  std::vector<Eigen::AlignedBox3d> boxes;
  for (size_t i = 0; i < msg.carve_min.size() && i < msg.carve_max.size(); ++i) {
    const auto& a = msg.carve_min[i];
    const auto& b = msg.carve_max[i];
    boxes.emplace_back(Eigen::Vector3d(a.x, a.y, a.z), Eigen::Vector3d(b.x, b.y, b.z));
  }
  return boxes;
}

}  // namespace fisheye_mapping
