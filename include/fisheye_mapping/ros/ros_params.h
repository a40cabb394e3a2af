// ROS-side helpers shared by the nodelets: parameters -> core types.
#ifndef FISHEYE_MAPPING_ROS_ROS_PARAMS_H_
#define FISHEYE_MAPPING_ROS_ROS_PARAMS_H_

#include <map>
#include <string>
#include <vector>

#include <dynamic_reconfigure/Config.h>
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
  bool get(const std::string& key, std::vector<std::string>& v) const override { return nh_.getParam(key, v); }
  bool get(const std::string& key, std::map<std::string, std::string>& v) const override {
    return nh_.getParam(key, v);
  }
  using ParamSource::get;

 private:
  ros::NodeHandle nh_;
};

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

// Fills a PlaneSweepConfig from private parameters of the same names
// (fronto_planes, near, far, ground_planes, ..., filters under the names of
// cfg/PlaneSweepFilters.cfg), starting from the core's defaults. The result
// is validated (std::invalid_argument names the field).
PlaneSweepConfig loadPlaneSweepConfig(const ros::NodeHandle& private_nh);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_ROS_PARAMS_H_
