// One generic test of every parameter declaration (ParamTable), in place of
// per-stage copies: for every table of every stage and nodelet,
//   - each parameter set to another valid value (worked out from its
//     declaration) is read back from a YAML map and from an in-memory table,
//   - a value of the wrong type, outside its range or not one of its choices
//     is refused naming the parameter,
//   - a run-time update over a running config changes only run-time fields;
// for every cfg/*.cfg: the same names, types, defaults and choices as the
// declarations' run-time parameters, no range of its own (dynamic_reconfigure
// clamps to it before the node sees a value, which would make a sentinel such
// as "0: no limit" reachable by clamping), and a refused request reports the
// running values back; the shipped YAML files use only declared names and
// give the declared defaults; docs/parameters.md is the generated text.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <climits>
#include <cmath>
#include <fstream>
#include <limits>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "fisheye_mapping/DepthMaskReconfigureConfig.h"
#include "fisheye_mapping/DetectorReconfigureConfig.h"
#include "fisheye_mapping/SyncReconfigureConfig.h"
#include "fisheye_mapping/DepthReconfigureConfig.h"
#include "fisheye_mapping/TsdfReconfigureConfig.h"
#include "fisheye_mapping/core/common/param_table.h"
#include "fisheye_mapping/core/depth/depth_stage.h"
#include "fisheye_mapping/core/detection/depth_mask.h"
#include "fisheye_mapping/core/detection/detector.h"
#include "fisheye_mapping/core/sync/frame_sync.h"
#include "fisheye_mapping/core/tsdf/tsdf_config.h"
#include "fisheye_mapping/ros/node_options.h"
#include "fisheye_mapping/ros/param_registry.h"
#include "fisheye_mapping/ros/ros_params.h"

namespace fm = fisheye_mapping;

namespace {

// Calls f on every table of the package.
template <class F>
void forEachTable(F f) {
  f(fm::FrameSyncConfig::params());
  f(fm::DepthStageConfig::params());
  f(fm::DetectorStageConfig::params());
  f(fm::DepthMaskConfig::params());
  f(fm::TsdfConfig::params());
  f(fm::FrameSyncNodeOptions::params());
  f(fm::DepthNodeOptions::params());
  f(fm::DetectorNodeOptions::params());
  f(fm::DepthMaskNodeOptions::params());
  f(fm::TsdfNodeOptions::params());
  f(fm::RigTfNodeOptions::params());
}

double asNumber(const fm::ParamValue& v) {
  return std::holds_alternative<int>(v) ? std::get<int>(v) : std::get<double>(v);
}

// Numbers tried as "another valid value" of a number parameter with default d.
std::vector<double> numberCandidates(const fm::ParamInfo& i, double d) {
  std::vector<double> c;
  if (std::isnan(d)) d = std::isfinite(i.range.min) && std::isfinite(i.range.max) ? 0.5 * (i.range.min + i.range.max) : 1.0;
  if (i.kind == fm::ParamKind::Int) return {d + 2, d - 2, d + 1, d + 10};
  if (std::isfinite(i.range.max)) c.push_back(d + 0.25 * (i.range.max - d));
  c.insert(c.end(), {d * 1.5 + 0.25, d * 0.5, d - 0.25, d + 0.125});
  return c;
}

// Another value of the parameter than its default that the whole config
// accepts (its range and the config's rules), or nothing.
template <class C>
std::optional<fm::ParamValue> otherValidValue(const fm::ParamTable<C>& table, const typename fm::ParamTable<C>::Entry& e) {
  const C defaults{};
  const fm::ParamValue d = e.get(defaults);
  std::vector<fm::ParamValue> candidates;
  switch (e.info.kind) {
    case fm::ParamKind::Bool: candidates = {!std::get<bool>(d)}; break;
    case fm::ParamKind::Int:
      for (double v : numberCandidates(e.info, asNumber(d))) candidates.push_back(int(v));
      break;
    case fm::ParamKind::Double:
      for (double v : numberCandidates(e.info, asNumber(d))) candidates.push_back(v);
      break;
    case fm::ParamKind::String: candidates = {std::get<std::string>(d) + "_x7"}; break;
    case fm::ParamKind::Enum:
      for (const auto& ch : e.info.choices)
        if (ch != std::get<std::string>(d)) candidates.push_back(ch);
      break;
    case fm::ParamKind::DoubleList: {
      std::vector<double> l = std::get<std::vector<double>>(d);
      if (l.empty()) l = std::vector<double>(e.info.list_size ? e.info.list_size : 2, 1.0);
      for (double& v : l) v = v * 1.5 + 0.25;
      candidates = {l};
      break;
    }
    case fm::ParamKind::StringList: candidates = {std::vector<std::string>{"cam3", "cam4"}}; break;
    case fm::ParamKind::StringMap: candidates = {std::map<std::string, std::string>{{"cam3", "/m/cam3.png"}}}; break;
  }
  for (const auto& v : candidates) {
    if (v == d) continue;
    try {
      C c = defaults;
      e.set(c, v);
      table.check(c);
      return v;
    } catch (const std::invalid_argument&) {
    }
  }
  return std::nullopt;
}

void putYaml(YAML::Node& node, const std::string& key, const fm::ParamValue& v) {
  std::visit([&](const auto& x) { node[key] = x; }, v);
}
void putMap(fm::MapParams& m, const std::string& key, const fm::ParamValue& v) {
  std::visit([&](const auto& x) { m.set(key, x); }, v);
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

// The message of the std::invalid_argument f throws ("" when it throws none).
template <class F>
std::string refusal(F f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(ParamDeclarations, EveryParameterIsReadFromYamlAndFromATable) {
  size_t checked = 0;
  forEachTable([&](const auto& table) {
    using C = typename std::decay_t<decltype(table)>::ConfigType;
    for (const auto& e : table.entries()) {
      const std::optional<fm::ParamValue> v = otherValidValue(table, e);
      ASSERT_TRUE(v) << table.section() << "/" << e.info.name << ": no valid value other than the default";
      YAML::Node y;
      putYaml(y, e.info.name, *v);
      fm::MapParams m;
      putMap(m, e.info.name, *v);
      const C from_yaml = table.read(fm::YamlParams(y), C{});
      const C from_map = table.read(m, C{});
      const fm::ParamValue got_yaml = table.values(from_yaml).at(e.info.name);
      const fm::ParamValue got_map = table.values(from_map).at(e.info.name);
      if (e.info.kind == fm::ParamKind::Double) {  // float fields round
        EXPECT_NEAR(asNumber(got_yaml), asNumber(*v), 1e-6 * std::max(1.0, std::abs(asNumber(*v)))) << e.info.name;
        EXPECT_NEAR(asNumber(got_map), asNumber(*v), 1e-6 * std::max(1.0, std::abs(asNumber(*v)))) << e.info.name;
      } else {
        EXPECT_EQ(got_yaml, *v) << table.section() << "/" << e.info.name << " from YAML: "
                                << fm::formatParamValue(got_yaml) << " for " << fm::formatParamValue(*v);
        EXPECT_EQ(got_map, *v) << table.section() << "/" << e.info.name;
      }
      // Nothing else changed.
      auto others = table.values(from_yaml);
      auto defaults = table.values(C{});
      others.erase(e.info.name);
      defaults.erase(e.info.name);
      if (e.info.name == "colour_range") continue;
      for (const auto& [name, value] : defaults) {
        if (std::holds_alternative<double>(value) && std::isnan(std::get<double>(value))) continue;
        EXPECT_EQ(others.at(name), value) << e.info.name << " changed " << name;
      }
      ++checked;
    }
  });
  EXPECT_GT(checked, 60u);
}

TEST(ParamDeclarations, WrongTypesAreRefusedNamingTheParameter) {
  forEachTable([&](const auto& table) {
    using C = typename std::decay_t<decltype(table)>::ConfigType;
    for (const auto& e : table.entries()) {
      const YAML::Node wrong = [&] {
        switch (e.info.kind) {
          case fm::ParamKind::String:
          case fm::ParamKind::Enum: return YAML::Load("[1, 2]");
          case fm::ParamKind::Bool: return YAML::Load("maybe");
          default: return YAML::Load("abc");
        }
      }();
      YAML::Node y;
      y[e.info.name] = wrong;
      const std::string msg = refusal([&] { table.read(fm::YamlParams(y, "f.yaml"), C{}); });
      EXPECT_TRUE(contains(msg, "'" + e.info.name + "'")) << e.info.name << ": " << msg;
      EXPECT_TRUE(contains(msg, "f.yaml")) << msg;
    }
  });
}

TEST(ParamDeclarations, ValuesOutsideTheRangeOrChoicesAreRefusedNamingTheParameter) {
  size_t checked = 0;
  forEachTable([&](const auto& table) {
    using C = typename std::decay_t<decltype(table)>::ConfigType;
    for (const auto& e : table.entries()) {
      const fm::ParamInfo& i = e.info;
      std::vector<fm::ParamValue> bad;
      if (i.kind == fm::ParamKind::Int || i.kind == fm::ParamKind::Double) {
        auto num = [&](double v) -> fm::ParamValue {
          if (i.kind == fm::ParamKind::Int) return int(v);
          return v;
        };
        if (std::isfinite(i.range.min)) bad.push_back(num(i.range.min_open ? i.range.min : i.range.min - 1));
        if (std::isfinite(i.range.max)) bad.push_back(num(i.range.max_open ? i.range.max : i.range.max + 1));
        if (i.kind == fm::ParamKind::Double) bad.push_back(std::numeric_limits<double>::quiet_NaN());
        if (i.kind == fm::ParamKind::Double) bad.push_back(std::numeric_limits<double>::infinity());
      } else if (i.kind == fm::ParamKind::Enum) {
        bad.push_back(std::string("bogus"));
      } else if (i.kind == fm::ParamKind::DoubleList && i.list_size) {
        bad.push_back(std::vector<double>(i.list_size + 1, 1.0));
      }
      for (const auto& v : bad) {
        fm::MapParams m;
        putMap(m, i.name, v);
        const std::string msg = refusal([&] { table.read(m, C{}); });
        EXPECT_EQ(msg.rfind(i.name + ":", 0), 0u) << i.name << " = " << fm::formatParamValue(v) << ": " << msg;
        if (i.kind == fm::ParamKind::Enum) {
          for (const auto& ch : i.choices) {
            EXPECT_TRUE(contains(msg, ch)) << msg;
          }
        }
        ++checked;
      }
    }
  });
  EXPECT_GT(checked, 80u);
}

// A run-time update (only the run-time names read) over a running config
// leaves every start-up field as it runs, even when the source holds them all.
TEST(ParamDeclarations, ARunTimeUpdateChangesOnlyRunTimeParameters) {
  forEachTable([&](const auto& table) {
    using C = typename std::decay_t<decltype(table)>::ConfigType;
    fm::MapParams all;
    std::map<std::string, fm::ParamValue> wanted;
    for (const auto& e : table.entries()) {
      if (e.info.name == "colour_range") continue;
      if (auto v = otherValidValue(table, e)) {
        putMap(all, e.info.name, *v);
        wanted[e.info.name] = *v;
      }
    }
    const C running{};
    const C next = table.read(all, running, /*runtime_only=*/true);
    const auto before = table.values(running), after = table.values(next);
    for (const auto& e : table.entries()) {
      const std::string& n = e.info.name;
      if (!wanted.count(n)) continue;
      if (e.info.runtime()) {
        if (e.info.kind == fm::ParamKind::Double)
          EXPECT_NEAR(asNumber(after.at(n)), asNumber(wanted.at(n)), 1e-6) << n;
        else
          EXPECT_EQ(after.at(n), wanted.at(n)) << n;
      } else if (!(std::holds_alternative<double>(before.at(n)) && std::isnan(std::get<double>(before.at(n))))) {
        EXPECT_EQ(after.at(n), before.at(n)) << n << " is start-up only";
      }
    }
  });
}

TEST(ParamDeclarations, EveryDeclarationIsDescribedAndItsDefaultIsValid) {
  std::set<std::string> time_reset_meanings;
  forEachTable([&](const auto& table) {
    using C = typename std::decay_t<decltype(table)>::ConfigType;
    EXPECT_NO_THROW(table.check(C{})) << table.section();
    for (const auto& i : table.documented()) {
      EXPECT_GT(i.description.size(), 10u) << i.name;
      if (i.kind == fm::ParamKind::Enum) {
        EXPECT_GE(i.choices.size(), 2u) << i.name;
      }
      if (i.name == "time_reset_threshold") {
        EXPECT_EQ(i.range.text(), ">= 0") << table.section();
        EXPECT_TRUE(contains(i.description, "0: never")) << table.section() << ": " << i.description;
        time_reset_meanings.insert(i.range.text());
      }
    }
  });
  EXPECT_EQ(time_reset_meanings.size(), 1u);
}

// The rules across fields hold through the tables that include others (the
// depth stage includes the sweep, which includes the filters).
TEST(ParamDeclarations, CrossFieldRulesHoldThroughIncludedTables) {
  const struct {
    std::string key;
    fm::ParamValue value;
    std::string named;
  } cases[] = {
      {"consistency_window", 4, "consistency_window: must be odd, got 4"},
      {"window_full", 8, "window_full: must be odd, got 8"},
      {"far", 1.0, "far: must be > 1.5 m (greater than near), got 1"},
      {"ground_max", -0.5, "ground_max: must be > -0.3 m (greater than ground_min), got -0.5"},
      {"ground_planes", 1, "ground_planes: must be 0 or at least 2, got 1"},
  };
  for (const auto& c : cases) {
    fm::MapParams m;
    putMap(m, c.key, c.value);
    EXPECT_EQ(refusal([&] { fm::DepthStageConfig::params().read(m, fm::DepthStageConfig()); }), c.named) << c.key;
    EXPECT_EQ(refusal([&] { fm::PlaneSweepConfig::params().read(m, fm::PlaneSweepConfig()); }), c.named) << c.key;
    EXPECT_EQ(refusal([&] { fm::DepthStageConfig::fromParams(m); }), c.named) << c.key;
  }
  fm::MapParams m;
  m.set("consistency_window", 4);
  EXPECT_EQ(refusal([&] { fm::DepthFilterConfig::fromParams(m); }), "consistency_window: must be odd, got 4");
  fm::MapParams colour;
  fm::MapParams shares;
  shares.set("moving_share", 0.5);
  EXPECT_EQ(refusal([&] { fm::DepthMaskConfig::fromParams(shares); }),
            "moving_share: must be [0, 0.5) (below static_share), got 0.5");
  colour.set("colour_range", std::vector<double>{30.0, 10.0});
  EXPECT_EQ(refusal([&] { fm::DepthMaskConfig::fromParams(colour); }),
            "colour_range: must be > 30 m (far greater than near), got 10");
  fm::DepthStageConfig direct;
  direct.sweep.filters.consistency_window = 6;  // set in code, not read: validate() applies the same rules
  EXPECT_EQ(refusal([&] { direct.validate(); }), "consistency_window: must be odd, got 6");
}

// ---------------------------------------------------------------------------
// cfg/*.cfg against the declarations

std::set<std::string> choicesOf(const std::string& edit_method) {
  std::set<std::string> s;
  const std::regex value("'value': '([^']*)'");
  for (auto it = std::sregex_iterator(edit_method.begin(), edit_method.end(), value); it != std::sregex_iterator(); ++it)
    s.insert((*it)[1]);
  return s;
}

const char* cfgType(fm::ParamKind k) {
  switch (k) {
    case fm::ParamKind::Bool: return "bool";
    case fm::ParamKind::Int: return "int";
    case fm::ParamKind::Double: return "double";
    case fm::ParamKind::String:
    case fm::ParamKind::Enum: return "str";
    default: return "?";
  }
}

template <class Msg>
std::optional<double> numberIn(const Msg& msg, const std::string& name) {
  for (const auto& p : msg.doubles)
    if (p.name == name) return p.value;
  for (const auto& p : msg.ints)
    if (p.name == name) return p.value;
  return std::nullopt;
}

// One refused request: `name` set to `bad` in the cfg's default request, over
// the table's default config running.
template <class Cfg, class C>
void expectRefusedAndReportedBack(const fm::ParamTable<C>& table, const fm::ParamInfo& info, double bad) {
  Cfg request = Cfg::__getDefault__();
  dynamic_reconfigure::Config msg;
  request.__toMessage__(msg);
  for (auto& p : msg.doubles)
    if (p.name == info.name) p.value = bad;
  for (auto& p : msg.ints)
    if (p.name == info.name) p.value = int(bad);
  request.__fromMessage__(msg);
  request.__clamp__();  // what the server does before the callback: must not change the value
  dynamic_reconfigure::Config sent;
  request.__toMessage__(sent);
  ASSERT_EQ(*numberIn(sent, info.name), info.kind == fm::ParamKind::Int ? double(int(bad)) : bad)
      << info.name << ": the .cfg clamps it";
  C running{};
  if constexpr (std::is_same_v<C, fm::DetectorStageConfig>) {  // as the nodelet runs: thresholds in effect
    running.score_threshold = 0.35f;
    running.nms_threshold = 0.5f;
  }
  std::string error;
  EXPECT_FALSE(fm::reconfigured(table, running, sent, error)) << info.name << " = " << bad;
  EXPECT_EQ(error.rfind(info.name + ":", 0), 0u) << error;
  fm::keepRunningValues(request, std::make_pair(std::cref(table), running));
  dynamic_reconfigure::Config back;
  request.__toMessage__(back);
  EXPECT_DOUBLE_EQ(*numberIn(back, info.name), asNumber(table.values(running).at(info.name)))
      << info.name << ": the running value is not reported back";
}

template <class Cfg, class... Tables>
void checkCfg(const std::string& cfg, const Tables&... tables) {
  SCOPED_TRACE(cfg);
  std::map<std::string, fm::ParamInfo> declared;
  (
      [&] {
        for (const auto& i : tables.documented())
          if (i.runtime()) declared[i.name] = i;
      }(),
      ...);
  const dynamic_reconfigure::ConfigDescription description = Cfg::__getDescriptionMessage__();
  dynamic_reconfigure::Config defaults, mins, maxs;
  Cfg::__getDefault__().__toMessage__(defaults);
  Cfg::__getMin__().__toMessage__(mins);
  Cfg::__getMax__().__toMessage__(maxs);
  std::set<std::string> in_cfg;
  for (const auto& g : description.groups) {
    for (const auto& p : g.parameters) {
      in_cfg.insert(p.name);
      auto it = declared.find(p.name);
      if (it == declared.end()) {
        ADD_FAILURE() << p.name << " is in " << cfg << " but no declared run-time parameter";
        continue;
      }
      const fm::ParamInfo& i = it->second;
      EXPECT_EQ(p.type, cfgType(i.kind)) << p.name;
      EXPECT_EQ(p.description, i.description) << p.name;
      if (i.kind == fm::ParamKind::Enum) {
        EXPECT_EQ(choicesOf(p.edit_method), std::set<std::string>(i.choices.begin(), i.choices.end())) << p.name;
      } else {
        EXPECT_EQ(p.edit_method, "") << p.name;
      }
      if (i.kind == fm::ParamKind::Int || i.kind == fm::ParamKind::Double) {
        if (!i.optional) {
          EXPECT_DOUBLE_EQ(*numberIn(defaults, p.name), asNumber(i.default_value)) << p.name;
        }
        const double lo = i.kind == fm::ParamKind::Int ? double(INT_MIN) : -std::numeric_limits<double>::infinity();
        const double hi = i.kind == fm::ParamKind::Int ? double(INT_MAX) : std::numeric_limits<double>::infinity();
        EXPECT_EQ(*numberIn(mins, p.name), lo) << p.name << ": a range in the .cfg clamps before the node checks";
        EXPECT_EQ(*numberIn(maxs, p.name), hi) << p.name << ": a range in the .cfg clamps before the node checks";
      }
      if (i.kind == fm::ParamKind::Bool) {
        for (const auto& b : defaults.bools)
          if (b.name == p.name) {
            EXPECT_EQ(bool(b.value), std::get<bool>(i.default_value)) << p.name;
          }
      }
      if (i.kind == fm::ParamKind::String || i.kind == fm::ParamKind::Enum) {
        for (const auto& s : defaults.strs)
          if (s.name == p.name) {
            EXPECT_EQ(s.value, std::get<std::string>(i.default_value)) << p.name;
          }
      }
    }
  }
  for (const auto& [name, info] : declared) EXPECT_TRUE(in_cfg.count(name)) << name << " is run-time but not in " << cfg;
  // Out-of-range requests are refused and the running value reported back.
  (
      [&] {
        for (const auto& i : tables.documented()) {
          if (!i.runtime() || !(i.kind == fm::ParamKind::Int || i.kind == fm::ParamKind::Double)) continue;
          if (std::isfinite(i.range.min)) expectRefusedAndReportedBack<Cfg>(tables, i, i.range.min - 3);
          if (std::isfinite(i.range.max)) expectRefusedAndReportedBack<Cfg>(tables, i, i.range.max + 3);
        }
      }(),
      ...);
}

TEST(ParamDeclarations, CfgFilesAreTheRunTimeDeclarationsWithoutRangesOfTheirOwn) {
  checkCfg<fisheye_mapping::SyncReconfigureConfig>("cfg/SyncReconfigure.cfg", fm::FrameSyncConfig::params());
  checkCfg<fisheye_mapping::DepthReconfigureConfig>("cfg/DepthReconfigure.cfg", fm::PlaneSweepConfig::params());
  checkCfg<fisheye_mapping::DetectorReconfigureConfig>("cfg/DetectorReconfigure.cfg",
                                                       fm::DetectorStageConfig::params());
  checkCfg<fisheye_mapping::DepthMaskReconfigureConfig>("cfg/DepthMaskReconfigure.cfg", fm::DepthMaskConfig::params());
  checkCfg<fisheye_mapping::TsdfReconfigureConfig>("cfg/TsdfReconfigure.cfg", fm::TsdfConfig::params(),
                                              fm::TsdfNodeOptions::params());
}

// The cases by hand: max_range -3 is not "no limit", 100000 is not
// clamped to 1000, near 80 is refused (far 60), policy bogus is refused.
TEST(ParamDeclarations, TheReportedReconfigureCasesAreRefusedOrKept) {
  std::string error;
  fm::TsdfConfig tsdf;
  tsdf.max_range = 15.0;
  fm::TsdfReconfigureConfig t = fm::TsdfReconfigureConfig::__getDefault__();
  t.max_range = -3;
  dynamic_reconfigure::Config msg;
  t.__toMessage__(msg);
  EXPECT_FALSE(fm::reconfigured(fm::TsdfConfig::params(), tsdf, msg, error));
  EXPECT_EQ(error, "max_range: must be >= 0 m, got -3");
  t.max_range = 100000;
  t.__toMessage__(msg);
  const auto far = fm::reconfigured(fm::TsdfConfig::params(), tsdf, msg, error);
  ASSERT_TRUE(far);
  EXPECT_EQ(far->max_range, 100000);

  fm::DepthReconfigureConfig p = fm::DepthReconfigureConfig::__getDefault__();
  p.near = 80;
  p.__toMessage__(msg);
  EXPECT_FALSE(fm::reconfigured(fm::PlaneSweepConfig::params(), fm::PlaneSweepConfig(), msg, error));
  EXPECT_TRUE(contains(error, "far")) << error;
  EXPECT_TRUE(contains(error, "80")) << error;

  fm::SyncReconfigureConfig s = fm::SyncReconfigureConfig::__getDefault__();
  s.policy = "bogus";
  s.__toMessage__(msg);
  EXPECT_FALSE(fm::reconfigured(fm::FrameSyncConfig::params(), fm::FrameSyncConfig(), msg, error));
  EXPECT_EQ(error, "policy: must be one of exact | approximate, got 'bogus'");
  fm::keepRunningValues(s, std::make_pair(std::cref(fm::FrameSyncConfig::params()), fm::FrameSyncConfig()));
  EXPECT_EQ(s.policy, "exact");
}

// ---------------------------------------------------------------------------
// The shipped YAML files and the docs

YAML::Node loadConfig(const std::string& name) { return YAML::LoadFile(std::string(FM_CONFIG_DIR) + "/" + name); }

// A stage's default file: only the node's names, each at its declared default.
void checkDefaultsFile(const std::string& file, const std::string& section) {
  SCOPED_TRACE(file);
  const YAML::Node y = loadConfig(file);
  const fm::NodeParamSet& set = fm::nodeParamSet(section);
  EXPECT_NO_THROW(set.requireKnown(fm::yamlKeys(y), file));
  const auto values = set.read(fm::YamlParams(y, file));
  std::map<std::string, fm::ParamValue> declared;
  for (const auto& i : set.stage) declared[i.name] = i.default_value;
  for (const auto& i : set.node) declared[i.name] = i.default_value;
  for (const auto& key : fm::yamlKeys(y)) {
    const fm::ParamValue& v = values.at(key);
    const fm::ParamValue& d = declared.at(key);
    if (std::holds_alternative<double>(v))
      EXPECT_NEAR(std::get<double>(v), std::get<double>(d), 1e-6 * std::max(1.0, std::abs(std::get<double>(d)))) << key;
    else
      EXPECT_EQ(v, d) << key << ": " << fm::formatParamValue(v) << " in the file, declared "
                      << fm::formatParamValue(d);
  }
}

TEST(ParamDeclarations, StageDefaultFilesUseOnlyDeclaredNamesAtTheirDefaults) {
  checkDefaultsFile("depth.yaml", "depth");
  checkDefaultsFile("tsdf.yaml", "tsdf");
}

TEST(ParamDeclarations, EverySectionOfVehicleYamlIsAStageAndUsesOnlyItsNames) {
  const YAML::Node y = loadConfig("vehicle.yaml");
  ASSERT_TRUE(y.IsMap());
  std::set<std::string> sections;
  for (const auto& kv : y) {
    const std::string section = kv.first.as<std::string>();
    sections.insert(section);
    const fm::NodeParamSet& set = fm::nodeParamSet(section);
    EXPECT_NO_THROW(set.requireKnown(fm::yamlKeys(kv.second), "vehicle.yaml")) << section;
    EXPECT_NO_THROW(set.read(fm::YamlParams(kv.second, "vehicle.yaml"))) << section;
  }
  EXPECT_TRUE(sections.count("tsdf"));
  // A typo is named with the section and the known names.
  const fm::NodeParamSet& tsdf = fm::nodeParamSet("tsdf");
  const std::string msg = refusal([&] { tsdf.requireKnown({"max_rnge"}, "vehicle.yaml"); });
  EXPECT_TRUE(contains(msg, "vehicle.yaml: unknown parameter 'max_rnge' in section 'tsdf'")) << msg;
  EXPECT_TRUE(contains(msg, "max_range")) << msg;
  EXPECT_TRUE(contains(refusal([] { fm::nodeParamSet("tsfd"); }), "unknown section 'tsfd'"));
}

TEST(ParamDeclarations, DocsParametersMdIsGeneratedFromTheDeclarations) {
  std::ifstream f(std::string(FM_DOCS_DIR) + "/parameters.md");
  ASSERT_TRUE(f) << "docs/parameters.md is missing";
  std::stringstream s;
  s << f.rdbuf();
  EXPECT_TRUE(s.str() == fm::parametersMarkdown())
      << "docs/parameters.md is out of date: rosrun fisheye_mapping param_docs > docs/parameters.md";
  // Each parameter of each node is in it.
  for (const auto& set : fm::nodeParamSets())
    for (const auto& n : set.names()) EXPECT_TRUE(contains(s.str(), "| `" + n + "` |")) << n;
}

}  // namespace
