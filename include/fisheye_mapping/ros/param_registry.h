// Every nodelet's parameters in one list: its stage's declarations (the core
// config's ParamTable) and its own (node_options.h), with the section of
// config/vehicle.yaml and the node name of launch/vehicle.launch they belong
// to. docs/parameters.md is generated from it (param_docs), and the generic
// test of cfg/*.cfg and config/*.yaml (test_param_declarations) walks it.
#ifndef FISHEYE_MAPPING_ROS_PARAM_REGISTRY_H_
#define FISHEYE_MAPPING_ROS_PARAM_REGISTRY_H_

#include <functional>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "fisheye_mapping/core/common/param_table.h"

namespace fisheye_mapping {

struct NodeParamSet {
  std::string section;       // node name in vehicle.launch = section of config/vehicle.yaml ("tsdf")
  std::string nodelet;       // "fisheye_mapping/Tsdf"
  std::string stage_struct;  // "TsdfConfig" (empty: no core stage)
  std::vector<ParamInfo> stage;
  std::string node_struct;   // "TsdfNodeOptions"
  std::vector<ParamInfo> node;
  std::string cfg;           // "cfg/TsdfReconfigure.cfg" (empty: none)
  // Reads every parameter of the node (stage and node options) from `p`
  // over the defaults and returns all their values by name; throws
  // std::invalid_argument naming a bad one.
  std::function<std::map<std::string, ParamValue>(const ParamSource& p)> read;
  // Every name the node accepts.
  std::set<std::string> names() const;
  // Throws std::invalid_argument naming the first key the node does not
  // declare, with the known ones; `origin` names the file.
  void requireKnown(const std::vector<std::string>& keys, const std::string& origin) const;
};

// sync, depth, detector, depth_mask, tsdf, rig_tf.
const std::vector<NodeParamSet>& nodeParamSets();
// Throws std::invalid_argument naming the section and the known ones.
const NodeParamSet& nodeParamSet(const std::string& section);

// docs/parameters.md.
std::string parametersMarkdown();

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_PARAM_REGISTRY_H_
