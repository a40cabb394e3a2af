#include "fisheye_mapping/ros/ros_params.h"

namespace fisheye_mapping {

Rig loadRigFromParams(const ros::NodeHandle& private_nh) {
  std::string camchain, mount;
  if (!private_nh.getParam("camchain", camchain) || camchain.empty()) {
    throw CalibrationError("parameter " + private_nh.resolveName("camchain") +
                           " (path of the Kalibr camchain YAML) is not set");
  }
  if (!private_nh.getParam("mount", mount) || mount.empty()) {
    throw CalibrationError("parameter " + private_nh.resolveName("mount") +
                           " (path of the mount YAML with T_base_cam0) is not set");
  }
  return loadKalibrRig(camchain, mount);
}

PlaneSweepConfig loadPlaneSweepConfig(const ros::NodeHandle& pnh) { return planeSweepConfigFrom(RosParams(pnh)); }

}  // namespace fisheye_mapping
