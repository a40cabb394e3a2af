// ROS-side helpers shared by the nodelets: parameters -> core types.
#ifndef FISHEYE_MAPPING_ROS_ROS_PARAMS_H_
#define FISHEYE_MAPPING_ROS_ROS_PARAMS_H_

#include <string>

#include <ros/node_handle.h>

#include "fisheye_mapping/core/plane_sweep.h"
#include "fisheye_mapping/core/rig.h"

namespace fisheye_mapping {

// Reads the private parameters `camchain` and `mount` (file paths) and loads
// the rig. Throws CalibrationError naming the missing parameter or the bad file.
Rig loadRigFromParams(const ros::NodeHandle& private_nh);

// Fills a PlaneSweepConfig from private parameters of the same names
// (fronto_planes, near, far, ground_planes, ..., filters under the names of
// cfg/PlaneSweepFilters.cfg), starting from the core's defaults. The result
// is validated (std::invalid_argument names the field).
PlaneSweepConfig loadPlaneSweepConfig(const ros::NodeHandle& private_nh);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_ROS_PARAMS_H_
