// Stage parameters from any key/value source (no ROS): one reading of each
// stage's parameter names serves both the nodelets (ROS parameter server) and
// the offline tools (YAML files such as config/plane_sweep_depth.yaml).
#ifndef FISHEYE_MAPPING_CORE_COMMON_PARAMS_H_
#define FISHEYE_MAPPING_CORE_COMMON_PARAMS_H_

#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "fisheye_mapping/core/depth/plane_sweep.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"

namespace fisheye_mapping {

/// A source of named parameters; get() leaves `v` alone and returns false when
/// the key is absent, and throws std::invalid_argument naming the key when its
/// value has the wrong type.
class ParamSource {
 public:
  virtual ~ParamSource() = default;
  virtual bool get(const std::string& key, double& v) const = 0;
  virtual bool get(const std::string& key, int& v) const = 0;
  virtual bool get(const std::string& key, bool& v) const = 0;
  virtual bool get(const std::string& key, std::string& v) const = 0;
  virtual bool get(const std::string& key, std::vector<double>& v) const = 0;
};

/// Parameters from a YAML map (e.g. one stage's section of config/vehicle.yaml).
class YamlParams : public ParamSource {
 public:
  explicit YamlParams(YAML::Node node, std::string origin = "YAML") : node_(std::move(node)), origin_(std::move(origin)) {}
  bool get(const std::string& key, double& v) const override { return read(key, v); }
  bool get(const std::string& key, int& v) const override { return read(key, v); }
  bool get(const std::string& key, bool& v) const override { return read(key, v); }
  bool get(const std::string& key, std::string& v) const override { return read(key, v); }
  bool get(const std::string& key, std::vector<double>& v) const override { return read(key, v); }

 private:
  template <class T>
  bool read(const std::string& key, T& v) const {
    if (!node_.IsMap() || !node_[key]) return false;
    try {
      v = node_[key].as<T>();
    } catch (const YAML::Exception&) {
      throw std::invalid_argument(origin_ + ": parameter '" + key + "' has the wrong type");
    }
    return true;
  }
  YAML::Node node_;
  std::string origin_;
};

/// Plane-sweep configuration from the parameter names of config/plane_sweep_depth.yaml
/// (filters as in cfg/PlaneSweepFilters.cfg), over the core defaults; validated.
PlaneSweepConfig planeSweepConfigFrom(const ParamSource& p);

/// TSDF configuration from the parameter names of config/tsdf_fusion.yaml; validated.
TsdfConfig tsdfConfigFrom(const ParamSource& p);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_PARAMS_H_
