// ROS-side helpers shared by the nodelets: parameters -> core types.
#ifndef FISHEYE_MAPPING_ROS_ROS_PARAMS_H_
#define FISHEYE_MAPPING_ROS_ROS_PARAMS_H_

#include <string>

#include <ros/node_handle.h>

#include "fisheye_mapping/core/common/params.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"
#include "fisheye_mapping/core/camera/rig.h"

namespace fisheye_mapping {

// Reads the private parameters `camchain` and `mount` (file paths) and loads
// the rig. Throws CalibrationError naming the missing parameter or the bad file.
Rig loadRigFromParams(const ros::NodeHandle& private_nh);

// The private parameters of a node as a core ParamSource.
class RosParams : public ParamSource {
 public:
  explicit RosParams(const ros::NodeHandle& nh) : nh_(nh) {}
  bool get(const std::string& key, double& v) const override { return nh_.getParam(key, v); }
  bool get(const std::string& key, int& v) const override { return nh_.getParam(key, v); }
  bool get(const std::string& key, bool& v) const override { return nh_.getParam(key, v); }
  bool get(const std::string& key, std::string& v) const override { return nh_.getParam(key, v); }
  bool get(const std::string& key, std::vector<double>& v) const override { return nh_.getParam(key, v); }

 private:
  ros::NodeHandle nh_;
};

// Fills a PlaneSweepConfig from private parameters of the same names
// (fronto_planes, near, far, ground_planes, ..., filters under the names of
// cfg/PlaneSweepFilters.cfg), starting from the core's defaults. The result
// is validated (std::invalid_argument names the field).
PlaneSweepConfig loadPlaneSweepConfig(const ros::NodeHandle& private_nh);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_ROS_PARAMS_H_
