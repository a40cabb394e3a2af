// Messages of the TSDF stage <-> its core values: the obstacle grid, the
// carve regions of parked vehicles that drove off.
#ifndef FISHEYE_MAPPING_ROS_TSDF_MESSAGES_H_
#define FISHEYE_MAPPING_ROS_TSDF_MESSAGES_H_

#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nav_msgs/OccupancyGrid.h>

#include "fisheye_mapping/TrackedVehicleArray.h"
#include "fisheye_mapping/core/tsdf/occupancy_grid.h"

namespace fisheye_mapping {

// The grid in `frame`, its origin at height `z` (the vehicle's ground, for rviz).
nav_msgs::OccupancyGrid toOccupancyGridMsg(const OccupancyGrid& grid, const std::string& frame, const ros::Time& stamp,
                                           double z);

// The carve regions (carve_min[i], carve_max[i]) as boxes; unpaired corners are ignored.
std::vector<Eigen::AlignedBox3d> carveRegions(const TrackedVehicleArray& msg);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_TSDF_MESSAGES_H_
