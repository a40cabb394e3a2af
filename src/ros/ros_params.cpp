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

namespace {
template <class List, class T>
bool findIn(const List& list, const std::string& key, T& v) {
  for (const auto& p : list) {
    if (p.name == key) {
      v = p.value;
      return true;
    }
  }
  return false;
}
}  // namespace

bool ReconfigureParams::get(const std::string& key, double& v) const {
  int i = 0;
  if (findIn(c_.doubles, key, v)) return true;
  if (findIn(c_.ints, key, i)) return v = i, true;
  return false;
}
bool ReconfigureParams::get(const std::string& key, int& v) const { return findIn(c_.ints, key, v); }
bool ReconfigureParams::get(const std::string& key, bool& v) const { return findIn(c_.bools, key, v); }
bool ReconfigureParams::get(const std::string& key, std::string& v) const { return findIn(c_.strs, key, v); }

PlaneSweepConfig loadPlaneSweepConfig(const ros::NodeHandle& pnh) { return PlaneSweepConfig::fromParams(RosParams(pnh)); }

}  // namespace fisheye_mapping
