#include "fisheye_mapping/ros/ros_params.h"

#include <ros/param.h>

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

std::set<std::string> privateParamNames(const ros::NodeHandle& pnh) {
  std::vector<std::string> all;
  std::set<std::string> names;
  if (!ros::param::getParamNames(all)) return names;
  const std::string prefix = pnh.getNamespace() + "/";
  for (const auto& n : all) {
    if (n.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string rest = n.substr(prefix.size());
    names.insert(rest.substr(0, rest.find('/')));
  }
  return names;
}

void requireKnownParams(const ros::NodeHandle& pnh, const std::vector<std::set<std::string>>& known) {
  std::set<std::string> all;
  for (const auto& k : known) all.insert(k.begin(), k.end());
  for (const auto& n : privateParamNames(pnh)) {
    if (all.count(n)) continue;
    std::string list;
    for (const auto& k : all) list += (list.empty() ? "" : ", ") + k;
    throw std::invalid_argument("unknown parameter " + pnh.resolveName(n) + " (known: " + list + ")");
  }
}

void putValues(dynamic_reconfigure::Config& msg, const std::map<std::string, ParamValue>& values) {
  for (auto& p : msg.bools)
    if (auto it = values.find(p.name); it != values.end() && std::holds_alternative<bool>(it->second))
      p.value = std::get<bool>(it->second);
  for (auto& p : msg.ints)
    if (auto it = values.find(p.name); it != values.end() && std::holds_alternative<int>(it->second))
      p.value = std::get<int>(it->second);
  for (auto& p : msg.doubles)
    if (auto it = values.find(p.name); it != values.end() && std::holds_alternative<double>(it->second) &&
                                       std::get<double>(it->second) == std::get<double>(it->second))  // not unset
      p.value = std::get<double>(it->second);
  for (auto& p : msg.strs)
    if (auto it = values.find(p.name); it != values.end() && std::holds_alternative<std::string>(it->second))
      p.value = std::get<std::string>(it->second);
}

}  // namespace fisheye_mapping
