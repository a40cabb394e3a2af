// The dynamic_reconfigure declaration of the depth filters
// (cfg/PlaneSweepFilters.cfg) checked against the one list of parameters the
// core reads (DepthFilterConfig::fromParams): the same names, the same
// defaults, and a range the core accepts end to end. The nodelet's reconfigure
// callback goes through ReconfigureParams and the same fromParams, so a name
// or default that drifts in either place fails here. No roscore needed.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "fisheye_mapping/PlaneSweepFiltersConfig.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"
#include "fisheye_mapping/ros/ros_params.h"

namespace fm = fisheye_mapping;

namespace {

fm::DepthFilterConfig filtersFrom(const fisheye_mapping::PlaneSweepFiltersConfig& c) {
  dynamic_reconfigure::Config msg;
  c.__toMessage__(msg);
  return fm::DepthFilterConfig::fromParams(fm::ReconfigureParams(msg));
}

bool same(const fm::DepthFilterConfig& a, const fm::DepthFilterConfig& b) {
  return a.texture == b.texture && a.min_texture_snr == b.min_texture_snr && a.min_noise_std == b.min_noise_std &&
         a.cost == b.cost && a.alpha_upper == b.alpha_upper && a.alpha_lower == b.alpha_lower &&
         a.split_row == b.split_row && a.uniqueness == b.uniqueness && a.max_ratio == b.max_ratio &&
         a.consistency == b.consistency && a.consistency_window == b.consistency_window && a.gamma == b.gamma &&
         a.delta == b.delta;
}

std::set<std::string> cfgNames() {
  std::set<std::string> names;
  for (const auto& d : fisheye_mapping::PlaneSweepFiltersConfig::__getParamDescriptions__()) names.insert(d->name);
  return names;
}

}  // namespace

// Every reconfigurable name is a parameter the core reads, and every filter
// parameter the core reads is reconfigurable, except the noise floor
// (min_noise_std, a property of the camera, set at start-up only).
TEST(ReconfigureParams, CfgNamesAreTheCoreFilterParameters) {
  fm::RecordingParams rec;
  fm::DepthFilterConfig::fromParams(rec);
  std::set<std::string> core = rec.asked();
  ASSERT_TRUE(core.count("min_noise_std"));
  core.erase("min_noise_std");
  EXPECT_EQ(cfgNames(), core);
  // The sweep's own fromParams reads the filters under the same names.
  fm::RecordingParams sweep;
  fm::PlaneSweepConfig::fromParams(sweep);
  for (const auto& n : rec.asked()) EXPECT_TRUE(sweep.asked().count(n)) << n;
}

// The .cfg defaults are the core's defaults (the paper's values).
TEST(ReconfigureParams, CfgDefaultsAreTheCoreDefaults) {
  const auto def = fisheye_mapping::PlaneSweepFiltersConfig::__getDefault__();
  EXPECT_TRUE(same(filtersFrom(def), fm::DepthFilterConfig()));
  // Hand-checked against Sec. III-A of the paper / the yaml documentation.
  EXPECT_DOUBLE_EQ(def.alpha_upper, 0.05);
  EXPECT_DOUBLE_EQ(def.alpha_lower, 0.3);
  EXPECT_EQ(def.consistency_window, 5);
}

// Each reconfigurable value reaches the core: moving one parameter to the end
// of its range (or flipping a switch) changes the core config, and the ends of
// every range are accepted by the core's validation (an odd window once the
// nodelet's sanitising made it odd).
TEST(ReconfigureParams, EveryCfgValueReachesTheCoreAndItsRangeIsValid) {
  using Cfg = fisheye_mapping::PlaneSweepFiltersConfig;
  const Cfg def = Cfg::__getDefault__(), lo = Cfg::__getMin__(), hi = Cfg::__getMax__();
  for (const auto& d : Cfg::__getParamDescriptions__()) {
    for (const Cfg* end : {&lo, &hi}) {
      Cfg c = def;
      boost::any v, dv;
      d->getValue(*end, v);
      d->getValue(def, dv);
      if (d->type == "bool") v = !boost::any_cast<bool>(dv);
      // Set just this parameter: through the message, by name.
      dynamic_reconfigure::Config msg;
      c.__toMessage__(msg);
      if (d->type == "bool") {
        for (auto& p : msg.bools) if (p.name == d->name) p.value = boost::any_cast<bool>(v);
      } else if (d->type == "int") {
        for (auto& p : msg.ints) if (p.name == d->name) p.value = boost::any_cast<int>(v) | 1;  // odd, as sanitised
      } else {
        for (auto& p : msg.doubles) if (p.name == d->name) p.value = boost::any_cast<double>(v);
      }
      fm::DepthFilterConfig f;
      ASSERT_NO_THROW(f = fm::DepthFilterConfig::fromParams(fm::ReconfigureParams(msg)))
          << d->name << " at the " << (end == &lo ? "minimum" : "maximum") << " of its .cfg range";
      const bool at_default = d->type == "int"    ? (boost::any_cast<int>(v) | 1) == boost::any_cast<int>(dv)
                              : d->type == "double" ? boost::any_cast<double>(v) == boost::any_cast<double>(dv)
                                                    : false;
      if (!at_default) EXPECT_FALSE(same(f, fm::DepthFilterConfig())) << d->name << " does not reach the core";
    }
  }
}
