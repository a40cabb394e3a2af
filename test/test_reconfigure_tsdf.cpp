// The dynamic_reconfigure declaration of the TSDF fusion (cfg/TsdfFusion.cfg)
// checked against the one list of parameters the core reads
// (TsdfConfig::fromParams) and against config/tsdf_fusion.yaml: the same
// names (every TSDF parameter is either reconfigurable or on the start-up
// list below, with its reason), the same defaults, and ranges the core accepts
// end to end. The nodelet's callback goes through ReconfigureParams and the
// same fromParams over its running config. No roscore needed.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include <yaml-cpp/yaml.h>

#include "fisheye_mapping/TsdfFusionConfig.h"
#include "fisheye_mapping/core/tsdf/tsdf_config.h"
#include "fisheye_mapping/ros/ros_params.h"

namespace fm = fisheye_mapping;
using Cfg = fisheye_mapping::TsdfFusionConfig;

namespace {

// TSDF parameters that need the map rebuilt, so start-up only (the .cfg's
// header says why for each).
const std::set<std::string> kStartupOnly = {"voxel_size",     "truncation_voxels", "max_weight",
                                            "local_map_size", "local_map_offset",  "swap_directory",
                                            "integrator",     "opencl_device",     "threads"};
// The nodelet's own reconfigurable parameter (not the core's).
const std::string kNodeParam = "publish_period";

std::set<std::string> cfgNames() {
  std::set<std::string> names;
  for (const auto& d : Cfg::__getParamDescriptions__()) names.insert(d->name);
  return names;
}

dynamic_reconfigure::Config message(const Cfg& c) {
  dynamic_reconfigure::Config msg;
  c.__toMessage__(msg);
  return msg;
}

// The fields the .cfg may change.
bool sameRuntime(const fm::TsdfConfig& a, const fm::TsdfConfig& b) {
  return a.max_range == b.max_range && a.min_observations == b.min_observations;
}

}  // namespace

TEST(ReconfigureTsdf, CfgNamesAreTheCoreParametersThatApplyAtRunTime) {
  fm::RecordingParams rec;
  fm::TsdfConfig::fromParams(rec);
  std::set<std::string> runtime;
  for (const std::string& n : rec.asked()) {
    if (!kStartupOnly.count(n)) runtime.insert(n);
  }
  for (const std::string& n : kStartupOnly) EXPECT_TRUE(rec.asked().count(n)) << n << " is no TSDF parameter (stale list)";
  runtime.insert(kNodeParam);
  EXPECT_EQ(cfgNames(), runtime);
  EXPECT_EQ(cfgNames(), (std::set<std::string>{"max_range", "min_observations", "publish_period"}));
}

// The .cfg defaults are the core's and the shipped yaml's.
TEST(ReconfigureTsdf, CfgDefaultsAreTheCoreAndYamlDefaults) {
  const Cfg def = Cfg::__getDefault__();
  const fm::TsdfConfig core = fm::TsdfConfig::fromParams(fm::ReconfigureParams(message(def)));
  EXPECT_TRUE(sameRuntime(core, fm::TsdfConfig()));
  const YAML::Node yaml = YAML::LoadFile(std::string(FM_CONFIG_DIR) + "/tsdf_fusion.yaml");
  EXPECT_DOUBLE_EQ(def.max_range, yaml["max_range"].as<double>());
  EXPECT_EQ(def.min_observations, yaml["min_observations"].as<int>());
  EXPECT_DOUBLE_EQ(def.publish_period, yaml["publish_period"].as<double>());
  // By hand: no range limit, 3 observations (docs/tsdf.md), 1 s updates.
  EXPECT_DOUBLE_EQ(def.max_range, 0.0);
  EXPECT_EQ(def.min_observations, 3);
  EXPECT_DOUBLE_EQ(def.publish_period, 1.0);
}

// Both ends of every TSDF range pass the core's validation and reach the
// config; the node's period stays positive.
TEST(ReconfigureTsdf, EveryCfgValueReachesTheCoreAndItsRangeIsValid) {
  const Cfg def = Cfg::__getDefault__(), lo = Cfg::__getMin__(), hi = Cfg::__getMax__();
  EXPECT_GT(lo.publish_period, 0.0);
  for (const auto& d : Cfg::__getParamDescriptions__()) {
    if (d->name == kNodeParam) continue;
    for (const Cfg* end : {&lo, &hi}) {
      dynamic_reconfigure::Config msg = message(def);
      boost::any v, dv;
      d->getValue(*end, v);
      d->getValue(def, dv);
      bool at_default = false;
      if (d->type == "int") {
        for (auto& p : msg.ints) if (p.name == d->name) p.value = boost::any_cast<int>(v);
        at_default = boost::any_cast<int>(v) == boost::any_cast<int>(dv);
      } else {
        for (auto& p : msg.doubles) if (p.name == d->name) p.value = boost::any_cast<double>(v);
        at_default = boost::any_cast<double>(v) == boost::any_cast<double>(dv);
      }
      fm::TsdfConfig c;
      ASSERT_NO_THROW(c = fm::TsdfConfig::fromParams(fm::ReconfigureParams(msg)))
          << d->name << " at the " << (end == &lo ? "minimum" : "maximum") << " of its .cfg range";
      if (!at_default) EXPECT_FALSE(sameRuntime(c, fm::TsdfConfig())) << d->name << " does not reach the core";
    }
  }
}

// Over a running config (as the nodelet applies it), an update changes the
// reconfigurable fields and keeps the start-up ones.
TEST(ReconfigureTsdf, UpdateOverARunningConfigKeepsTheStartupFields) {
  fm::TsdfConfig running;
  running.voxel_size = 0.1;
  running.truncation_voxels = 3.0;
  running.max_weight = 20.0f;
  running.local_map_size = Eigen::Vector3d(10, 20, 5);
  running.swap_directory = "/tmp/swap";
  Cfg c = Cfg::__getDefault__();
  c.max_range = 7.5;
  c.min_observations = 5;
  const fm::TsdfConfig next = fm::TsdfConfig::fromParams(fm::ReconfigureParams(message(c)), running);
  EXPECT_DOUBLE_EQ(next.max_range, 7.5);
  EXPECT_EQ(next.min_observations, 5);
  EXPECT_DOUBLE_EQ(next.voxel_size, 0.1);
  EXPECT_DOUBLE_EQ(next.truncation_voxels, 3.0);
  EXPECT_FLOAT_EQ(next.max_weight, 20.0f);
  EXPECT_EQ(next.local_map_size, Eigen::Vector3d(10, 20, 5));
  EXPECT_EQ(next.swap_directory, "/tmp/swap");
}
