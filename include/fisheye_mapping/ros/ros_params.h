// ROS-side helpers shared by the nodelets: parameters -> core types.
#ifndef FISHEYE_MAPPING_ROS_ROS_PARAMS_H_
#define FISHEYE_MAPPING_ROS_ROS_PARAMS_H_

#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <dynamic_reconfigure/Config.h>
#include <ros/node_handle.h>

#include "fisheye_mapping/core/common/param_table.h"
#include "fisheye_mapping/core/common/params.h"
#include "fisheye_mapping/core/camera/rig.h"

namespace fisheye_mapping {

// Reads the private parameters `camchain` and `mount` (file paths) and loads
// the rig. Throws CalibrationError naming the missing parameter or the bad file.
Rig loadRigFromParams(const ros::NodeHandle& private_nh);

// The private parameters of a node as a core ParamSource. A parameter that is
// set but of another type throws std::invalid_argument naming it (a wrongly
// typed value is never silently replaced by the default).
class RosParams : public ParamSource {
 public:
  explicit RosParams(const ros::NodeHandle& nh) : nh_(nh) {}
  bool get(const std::string& key, double& v) const override { return read(key, v); }
  bool get(const std::string& key, int& v) const override { return read(key, v); }
  bool get(const std::string& key, bool& v) const override { return read(key, v); }
  bool get(const std::string& key, std::string& v) const override { return read(key, v); }
  bool get(const std::string& key, std::vector<double>& v) const override { return read(key, v); }
  bool get(const std::string& key, std::vector<std::string>& v) const override { return read(key, v); }
  bool get(const std::string& key, std::map<std::string, std::string>& v) const override { return read(key, v); }
  using ParamSource::get;

 private:
  template <class T>
  bool read(const std::string& key, T& v) const {
    if (nh_.getParam(key, v)) return true;
    if (nh_.hasParam(key))
      throw std::invalid_argument("parameter " + nh_.resolveName(key) + " has the wrong type");
    return false;
  }
  ros::NodeHandle nh_;
};

// The names directly under a node's private namespace on the parameter
// server ("self_masks" for ~self_masks/cam1).
std::set<std::string> privateParamNames(const ros::NodeHandle& private_nh);

// Throws std::invalid_argument naming the first private parameter of the node
// that none of `known` declares, with the known names: a typo in a YAML section
// or a launch file stops the stage instead of being ignored.
void requireKnownParams(const ros::NodeHandle& private_nh, const std::vector<std::set<std::string>>& known);



// The values of a dynamic_reconfigure configuration (Config::__toMessage__)
// as a core ParamSource, so that a reconfigure callback fills the core config
// through the same fromParams() as the node's start-up parameters: no
// parameter name is mapped twice. Lists and maps are never present.
class ReconfigureParams : public ParamSource {
 public:
  explicit ReconfigureParams(dynamic_reconfigure::Config config) : c_(std::move(config)) {}
  bool get(const std::string& key, double& v) const override;
  bool get(const std::string& key, int& v) const override;
  bool get(const std::string& key, bool& v) const override;
  bool get(const std::string& key, std::string& v) const override;
  bool get(const std::string& key, std::vector<double>&) const override { return false; }
  bool get(const std::string& key, std::vector<std::string>&) const override { return false; }
  bool get(const std::string& key, std::map<std::string, std::string>&) const override { return false; }
  using ParamSource::get;

 private:
  dynamic_reconfigure::Config c_;
};

// ---- dynamic_reconfigure through the declarations ----
// `running` overlaid with the run-time parameters of `table` found in the
// request; every value checked against its declaration. A value outside its
// declared range (or not one of its choices) returns nullopt and `error`
// names it; nothing is clamped.
template <class C>
std::optional<C> reconfigured(const ParamTable<C>& table, const C& running, const dynamic_reconfigure::Config& request,
                              std::string& error);
// Writes `values` into the request's fields of the same names and types, so a
// refused request reports the kept values back to the caller (dynparam get).
void putValues(dynamic_reconfigure::Config& request, const std::map<std::string, ParamValue>& values);

template <class C>
std::optional<C> reconfigured(const ParamTable<C>& table, const C& running, const dynamic_reconfigure::Config& request,
                              std::string& error) {
  try {
    return table.read(ReconfigureParams(request), running, /*runtime_only=*/true);
  } catch (const std::exception& e) {
    error = e.what();
    return std::nullopt;
  }
}

// A generated reconfigure config (`Cfg`) set back to the running values of
// the given (table, config) pairs after a refused request.
template <class Cfg, class... Tables>
void keepRunningValues(Cfg& request, const Tables&... running) {
  dynamic_reconfigure::Config msg;
  request.__toMessage__(msg);
  (putValues(msg, running.first.values(running.second, /*runtime_only=*/true)), ...);
  request.__fromMessage__(msg);
}

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_ROS_PARAMS_H_
