// The dynamic_reconfigure declarations of the depth stage
// (cfg/PlaneSweepFilters.cfg: the filters and the sweep's planes / view
// thresholds) and of the frame sync (cfg/FrameSyncReconfigure.cfg) checked against the
// one list of parameters the core reads (PlaneSweepConfig::fromParams,
// FrameSyncConfig::fromParams): the same names, the same defaults, and a range
// the core accepts end to end. The nodelets' reconfigure callbacks go through
// ReconfigureParams and the same fromParams, so a name or default that drifts
// in either place fails here. No roscore needed.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "fisheye_mapping/PlaneSweepFiltersConfig.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/ros/ros_params.h"

#include "fisheye_mapping/FrameSyncReconfigureConfig.h"

namespace fm = fisheye_mapping;

namespace {

using SyncCfg = fm::FrameSyncReconfigureConfig;

fm::DepthFilterConfig filtersFrom(const fisheye_mapping::PlaneSweepFiltersConfig& c) {
  dynamic_reconfigure::Config msg;
  c.__toMessage__(msg);
  return fm::DepthFilterConfig::fromParams(fm::ReconfigureParams(msg));
}

fm::PlaneSweepConfig sweepFrom(const dynamic_reconfigure::Config& msg) {
  return fm::PlaneSweepConfig::fromParams(fm::ReconfigureParams(msg));
}

bool same(const fm::DepthFilterConfig& a, const fm::DepthFilterConfig& b) {
  return a.texture == b.texture && a.min_texture_snr == b.min_texture_snr && a.min_noise_std == b.min_noise_std &&
         a.cost == b.cost && a.alpha_upper == b.alpha_upper && a.alpha_lower == b.alpha_lower &&
         a.split_row == b.split_row && a.uniqueness == b.uniqueness && a.max_ratio == b.max_ratio &&
         a.consistency == b.consistency && a.consistency_window == b.consistency_window && a.gamma == b.gamma &&
         a.delta == b.delta;
}

// The sweep's reconfigurable fields besides the filters.
bool sameSweep(const fm::PlaneSweepConfig& a, const fm::PlaneSweepConfig& b) {
  return a.near == b.near && a.far == b.far && a.ground_height == b.ground_height && a.ground_min == b.ground_min &&
         a.ground_max == b.ground_max && a.min_parallax_px == b.min_parallax_px &&
         a.min_parallax_ratio == b.min_parallax_ratio && a.min_overlap == b.min_overlap && same(a.filters, b.filters);
}

bool sameSync(const fm::FrameSyncConfig& a, const fm::FrameSyncConfig& b) {
  return a.policy == b.policy && a.max_interval == b.max_interval && a.queue_size == b.queue_size &&
         a.silent_warning == b.silent_warning && a.time_reset_threshold == b.time_reset_threshold;
}

template <class Cfg>
std::set<std::string> cfgNames() {
  std::set<std::string> names;
  for (const auto& d : Cfg::__getParamDescriptions__()) names.insert(d->name);
  return names;
}

std::set<std::string> cfgNames() { return cfgNames<fisheye_mapping::PlaneSweepFiltersConfig>(); }

// `def` with the parameter of `d` moved to its value in `end` (a bool flipped;
// an int made odd, as the depth nodelet sanitises its window), as a message.
template <class Cfg, class Desc>
dynamic_reconfigure::Config withOneMoved(const Cfg& def, const Cfg& end, const Desc& d, bool* at_default) {
  boost::any v, dv;
  d->getValue(end, v);
  d->getValue(def, dv);
  dynamic_reconfigure::Config msg;
  def.__toMessage__(msg);
  *at_default = false;
  if (d->type == "bool") {
    for (auto& p : msg.bools) if (p.name == d->name) p.value = !boost::any_cast<bool>(dv);
  } else if (d->type == "int") {
    const int x = boost::any_cast<int>(v) | 1;
    *at_default = x == boost::any_cast<int>(dv);
    for (auto& p : msg.ints) if (p.name == d->name) p.value = x;
  } else if (d->type == "double") {
    *at_default = boost::any_cast<double>(v) == boost::any_cast<double>(dv);
    for (auto& p : msg.doubles) if (p.name == d->name) p.value = boost::any_cast<double>(v);
  } else {  // str: an enum's other value is tested by hand
    *at_default = true;
  }
  return msg;
}

}  // namespace

// Every reconfigurable name is a parameter the core's sweep reads, and every
// filter parameter the core reads is reconfigurable, except the noise floor
// (min_noise_std, a property of the camera, set at start-up only).
TEST(ReconfigureParams, CfgNamesAreTheCoreFilterParameters) {
  fm::RecordingParams rec;
  fm::DepthFilterConfig::fromParams(rec);
  std::set<std::string> core = rec.asked();
  ASSERT_TRUE(core.count("min_noise_std"));
  core.erase("min_noise_std");
  const std::set<std::string> names = cfgNames();
  for (const auto& n : core) EXPECT_TRUE(names.count(n)) << n << " is not reconfigurable";
  // The sweep's own fromParams reads the filters and the rest under the same names.
  fm::RecordingParams sweep;
  fm::PlaneSweepConfig::fromParams(sweep);
  for (const auto& n : rec.asked()) EXPECT_TRUE(sweep.asked().count(n)) << n;
  for (const auto& n : names) EXPECT_TRUE(sweep.asked().count(n)) << n << " is not a sweep parameter";
  // The run-time thresholds of the issue, by name.
  for (const char* n : {"near", "far", "ground_height", "ground_min", "ground_max", "min_parallax_px"})
    EXPECT_TRUE(names.count(n)) << n;
}

// cfg/FrameSyncReconfigure.cfg: every name FrameSyncConfig reads but the topic list (the
// subscriptions' order is fixed at start-up).
TEST(ReconfigureParams, SyncCfgNamesAreTheCoreSyncParameters) {
  fm::RecordingParams rec;
  fm::FrameSyncConfig::fromParams(rec);
  std::set<std::string> core = rec.asked();
  ASSERT_TRUE(core.count("image_topics"));
  core.erase("image_topics");
  EXPECT_EQ(cfgNames<SyncCfg>(), core);
}

TEST(ReconfigureParams, SyncCfgDefaultsAreTheCoreDefaultsAndEveryValueReachesIt) {
  const SyncCfg def = SyncCfg::__getDefault__(), lo = SyncCfg::__getMin__(), hi = SyncCfg::__getMax__();
  dynamic_reconfigure::Config msg;
  def.__toMessage__(msg);
  EXPECT_TRUE(sameSync(fm::FrameSyncConfig::fromParams(fm::ReconfigureParams(msg)), fm::FrameSyncConfig()));
  EXPECT_EQ(def.policy, "exact");
  EXPECT_DOUBLE_EQ(def.max_interval, 0.005);
  for (const auto& d : SyncCfg::__getParamDescriptions__()) {
    for (const SyncCfg* end : {&lo, &hi}) {
      bool at_default = false;
      const auto m = withOneMoved(def, *end, d, &at_default);
      fm::FrameSyncConfig c;
      ASSERT_NO_THROW(c = fm::FrameSyncConfig::fromParams(fm::ReconfigureParams(m)))
          << d->name << " at the " << (end == &lo ? "minimum" : "maximum") << " of its .cfg range";
      if (!at_default) EXPECT_FALSE(sameSync(c, fm::FrameSyncConfig())) << d->name << " does not reach the core";
    }
  }
  // The policy enum's other value.
  for (auto& p : msg.strs) if (p.name == "policy") p.value = "approximate";
  EXPECT_EQ(fm::FrameSyncConfig::fromParams(fm::ReconfigureParams(msg)).policy, fm::SyncPolicy::Approximate);
}

// The .cfg defaults are the core's defaults (the paper's values).
TEST(ReconfigureParams, CfgDefaultsAreTheCoreDefaults) {
  const auto def = fisheye_mapping::PlaneSweepFiltersConfig::__getDefault__();
  EXPECT_TRUE(same(filtersFrom(def), fm::DepthFilterConfig()));
  dynamic_reconfigure::Config msg;
  def.__toMessage__(msg);
  EXPECT_TRUE(sameSweep(sweepFrom(msg), fm::PlaneSweepConfig()));
  EXPECT_DOUBLE_EQ(def.ground_height, 0.0);
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
      bool at_default = false;
      const auto msg = withOneMoved(def, *end, d, &at_default);
      fm::PlaneSweepConfig c;
      ASSERT_NO_THROW(c = sweepFrom(msg)) << d->name << " at the " << (end == &lo ? "minimum" : "maximum")
                                          << " of its .cfg range";
      if (!at_default) EXPECT_FALSE(sameSweep(c, fm::PlaneSweepConfig())) << d->name << " does not reach the core";
    }
  }
}
