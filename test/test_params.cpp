// Stage configurations from their parameters (issue 14): each config struct's
// fromParams() over a ParamSource gives the documented defaults, reads every
// parameter name, rejects wrongly typed and out-of-range values naming the key
// or field, parses its enumerations once, and reads a YAML map (YamlParams)
// the same as an in-memory table (MapParams). The shipped YAML files use no
// parameter name that no stage reads (a typo'd name would be ignored).
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "fisheye_mapping/core/common/params.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"
#include "fisheye_mapping/core/detection/depth_mask.h"
#include "fisheye_mapping/core/detection/detector.h"
#include "fisheye_mapping/core/sync/frame_sync.h"

namespace fm = fisheye_mapping;

namespace {

using fm::RecordingParams;  // core/common/params.h

// The type of a parameter, for wrongly typed values.
enum class Kind { Number, Int, Bool, String, Vector };
struct Param {
  std::string name;
  Kind kind;
};

// Every parameter of each stage, as documented (config/plane_sweep_depth.yaml,
// cfg/PlaneSweepFilters.cfg, the nodelets' headers).
const std::vector<Param> kSweepParams = {
    {"fronto_planes", Kind::Int},        {"near", Kind::Number},
    {"far", Kind::Number},               {"ground_planes", Kind::Int},
    {"ground_min", Kind::Number},        {"ground_max", Kind::Number},
    {"ground_height", Kind::Number},
    {"window_full", Kind::Int},          {"window_half", Kind::Int},
    {"aggregation", Kind::String},       {"best_k", Kind::Int},
    {"subpixel", Kind::Bool},            {"resolution", Kind::String},
    {"crop_width", Kind::Number},        {"crop_height", Kind::Number},
    {"min_parallax_px", Kind::Number},   {"min_parallax_ratio", Kind::Number},
    {"min_overlap", Kind::Number},       {"backend", Kind::String},
    {"device", Kind::String},            {"filter_texture", Kind::Bool},
    {"min_texture_snr", Kind::Number},   {"min_noise_std", Kind::Number},
    {"filter_cost", Kind::Bool},         {"alpha_upper", Kind::Number},
    {"alpha_lower", Kind::Number},       {"split_row", Kind::Number},
    {"filter_uniqueness", Kind::Bool},   {"max_ratio", Kind::Number},
    {"filter_consistency", Kind::Bool},  {"consistency_window", Kind::Int},
    {"gamma", Kind::Number},             {"delta", Kind::Number},
};
// The plane-sweep depth nodelet's own parameters next to the sweep's (the
// depth stage: view selection and outputs), also in config/plane_sweep_depth.yaml.
const std::vector<std::string> kDepthStageNames = {"reference_camera", "support_cameras", "self_masks",
                                                   "publish_uniqueness", "time_reset_threshold"};
const std::vector<Param> kDetectorParams = {
    {"model_config", Kind::String}, {"score_threshold", Kind::Number}, {"nms_threshold", Kind::Number},
    {"dnn_backend", Kind::String},  {"dnn_target", Kind::String},      {"only_moving", Kind::Bool},
    {"publish_annotated", Kind::Bool},
};
const std::vector<Param> kMaskParams = {
    {"margin_px", Kind::Number},    {"wait_for_detections", Kind::Number},  {"max_pending", Kind::Int},
    {"colour_range", Kind::Vector}, {"time_reset_threshold", Kind::Number},
};
const std::vector<Param> kSyncParams = {
    {"policy", Kind::String},         {"max_interval", Kind::Number},         {"queue_size", Kind::Int},
    {"silent_warning", Kind::Number}, {"time_reset_threshold", Kind::Number}, {"image_topics", Kind::Vector},
};
// Nodelet parameters that are no stage's configuration (the rig, ROS transport).
const std::vector<std::string> kDetectorRosNames = {"image_transport"};
const std::vector<std::string> kSyncRosNames = {"camchain", "mount", "image_transport"};

std::set<std::string> namesOf(const std::vector<Param>& params) {
  std::set<std::string> s;
  for (const auto& p : params) s.insert(p.name);
  return s;
}

// The keys fromParams asks for.
template <class Config>
std::set<std::string> keysRead() {
  const fm::MapParams empty;
  const RecordingParams rec(empty);
  (void)Config::fromParams(rec);
  return rec.asked();
}

// Runs f, expecting std::invalid_argument whose message contains every one of `parts`.
void expectInvalid(const std::function<void()>& f, const std::vector<std::string>& parts, const std::string& what) {
  try {
    f();
    ADD_FAILURE() << what << ": no error";
  } catch (const std::invalid_argument& e) {
    for (const auto& p : parts) EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << what << ": " << e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << what << ": not std::invalid_argument: " << e.what();
  }
}

// Every parameter set to a value of the wrong type: the error names the key,
// from a MapParams and from a YAML map alike.
template <class Config>
void expectWrongTypesRejected(const std::vector<Param>& params) {
  for (const auto& p : params) {
    fm::MapParams m;
    std::string yaml;
    switch (p.kind) {
      case Kind::Number: m.set(p.name, "x"), yaml = p.name + ": [1, 2]"; break;
      case Kind::Int: m.set(p.name, 2.5), yaml = p.name + ": 2.5"; break;
      case Kind::Bool: m.set(p.name, "x"), yaml = p.name + ": maybe"; break;
      case Kind::String: m.set(p.name, 7), yaml = p.name + ": [a, b]"; break;
      case Kind::Vector: m.set(p.name, "x"), yaml = p.name + ": x"; break;
    }
    expectInvalid([&] { (void)Config::fromParams(m); }, {"'" + p.name + "'", "wrong type"}, "MapParams " + p.name);
    const fm::YamlParams y(YAML::Load(yaml), "test.yaml");
    expectInvalid([&] { (void)Config::fromParams(y); }, {"test.yaml", "'" + p.name + "'", "wrong type"},
                  "YAML " + yaml);
  }
}

// The same values as a MapParams and as a YAML map.
struct Both {
  fm::MapParams map;
  std::ostringstream yaml;
  void set(const std::string& k, double v) {
    map.set(k, v);
    yaml.precision(17);
    yaml << k << ": " << v << "\n";
  }
  void set(const std::string& k, int v) {
    map.set(k, v);
    yaml << k << ": " << v << "\n";
  }
  void set(const std::string& k, bool v) {
    map.set(k, v);
    yaml << k << ": " << (v ? "true" : "false") << "\n";
  }
  void set(const std::string& k, const char* v) {
    map.set(k, v);
    yaml << k << ": \"" << v << "\"\n";
  }
  fm::YamlParams yamlParams() const { return fm::YamlParams(YAML::Load(yaml.str()), "test.yaml"); }
};

std::string describe(const fm::PlaneSweepConfig& c) {
  std::ostringstream s;
  s.precision(17);
  const fm::DepthFilterConfig& f = c.filters;
  s << c.fronto_planes << " " << c.near << " " << c.far << " " << c.ground_planes << " " << c.ground_min << " "
    << c.ground_max << " " << c.window_full << " " << c.window_half << " " << fm::toString(c.aggregation) << " "
    << c.best_k << " " << c.subpixel << " " << fm::toString(c.resolution) << " " << c.crop_width << " "
    << c.crop_height << " " << c.min_parallax_px << " " << c.min_parallax_ratio << " " << c.min_overlap << " "
    << fm::toString(c.backend) << " '" << c.device << "' " << c.band_rows << " | " << f.texture << " "
    << f.min_texture_snr << " " << f.min_noise_std << " " << f.cost << " " << f.alpha_upper << " " << f.alpha_lower
    << " " << f.split_row << " " << f.uniqueness << " " << f.max_ratio << " " << f.consistency << " "
    << f.consistency_window << " " << f.gamma << " " << f.delta;
  return s.str();
}

std::string describe(const fm::DetectorStageConfig& c) {
  std::ostringstream s;
  s.precision(9);
  s << "'" << c.model_config << "' " << (c.score_threshold ? std::to_string(*c.score_threshold) : "-") << " "
    << (c.nms_threshold ? std::to_string(*c.nms_threshold) : "-") << " " << fm::toString(c.dnn_backend) << " "
    << fm::toString(c.dnn_target) << " " << c.only_moving << " " << c.publish_annotated;
  return s.str();
}

std::string describe(const fm::DepthMaskConfig& c) {
  std::ostringstream s;
  s.precision(17);
  s << c.margin_px << " " << c.wait_for_detections << " " << c.max_pending << " " << c.time_reset_threshold << " "
    << c.colour_near << " " << c.colour_far;
  return s.str();
}

std::string describe(const fm::FrameSyncConfig& c) {
  std::ostringstream s;
  s.precision(17);
  s << fm::toString(c.policy) << " " << c.max_interval << " " << c.queue_size << " " << c.silent_warning << " "
    << c.time_reset_threshold << " [";
  for (const auto& t : c.image_topics) s << t << ",";
  s << "]";
  return s.str();
}

std::set<std::string> yamlKeys(const YAML::Node& node) {
  std::set<std::string> keys;
  if (!node || !node.IsMap()) return keys;
  for (const auto& kv : node) keys.insert(kv.first.as<std::string>());
  return keys;
}

// Keys of `section` that are not in `known`.
std::vector<std::string> unknownKeys(const YAML::Node& section, const std::set<std::string>& known) {
  std::vector<std::string> out;
  for (const auto& k : yamlKeys(section))
    if (!known.count(k)) out.push_back(k);
  return out;
}

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : ", ") + x;
  return s;
}

}  // namespace

// ---------------------------------------------------------------------------
// PlaneSweepConfig (and its DepthFilterConfig)

TEST(PlaneSweepParams, EmptyParamsGiveTheDocumentedDefaults) {
  const fm::PlaneSweepConfig c = fm::PlaneSweepConfig::fromParams(fm::MapParams());
  EXPECT_EQ(c.fronto_planes, 64);
  EXPECT_DOUBLE_EQ(c.near, 1.5);
  EXPECT_DOUBLE_EQ(c.far, 60.0);
  EXPECT_EQ(c.ground_planes, 30);
  EXPECT_DOUBLE_EQ(c.ground_min, -0.3);
  EXPECT_DOUBLE_EQ(c.ground_max, 0.3);
  EXPECT_EQ(c.window_full, 9);
  EXPECT_EQ(c.window_half, 7);
  EXPECT_EQ(c.aggregation, fm::SweepAggregation::Average);
  EXPECT_EQ(c.best_k, 2);
  EXPECT_TRUE(c.subpixel);
  EXPECT_EQ(c.resolution, fm::SweepResolution::Multiscale);
  EXPECT_NEAR(c.crop_width, 0.5586, 1e-4);   // 572 / 1024
  EXPECT_NEAR(c.crop_height, 0.6103, 1e-4);  // 332 / 544
  EXPECT_DOUBLE_EQ(c.min_parallax_px, 0.25);
  EXPECT_DOUBLE_EQ(c.min_parallax_ratio, 0.33);
  EXPECT_DOUBLE_EQ(c.min_overlap, 0.2);
  EXPECT_EQ(c.backend, fm::SweepBackendType::Auto);
  EXPECT_EQ(c.device, "");
  EXPECT_EQ(c.band_rows, 32);
  const fm::DepthFilterConfig& f = c.filters;
  EXPECT_TRUE(f.texture);
  EXPECT_DOUBLE_EQ(f.min_texture_snr, 1.5);
  EXPECT_NEAR(f.min_noise_std, 0.0039, 1e-4);  // one 8-bit step
  EXPECT_TRUE(f.cost);
  EXPECT_DOUBLE_EQ(f.alpha_upper, 0.05);
  EXPECT_DOUBLE_EQ(f.alpha_lower, 0.3);
  EXPECT_DOUBLE_EQ(f.split_row, 0.5);
  EXPECT_TRUE(f.uniqueness);
  EXPECT_DOUBLE_EQ(f.max_ratio, 0.9);
  EXPECT_TRUE(f.consistency);
  EXPECT_EQ(f.consistency_window, 5);
  EXPECT_DOUBLE_EQ(f.gamma, 0.5);
  EXPECT_DOUBLE_EQ(f.delta, 0.3);
  // The same as a default-constructed config.
  EXPECT_EQ(describe(c), describe(fm::PlaneSweepConfig()));
}

TEST(PlaneSweepParams, ReadsExactlyTheDocumentedNames) {
  EXPECT_EQ(keysRead<fm::PlaneSweepConfig>(), namesOf(kSweepParams));
}

TEST(PlaneSweepParams, EveryParameterIsRead) {
  Both b;
  b.set("fronto_planes", 32);
  b.set("near", 2.0);
  b.set("far", 50.0);
  b.set("ground_planes", 10);
  b.set("ground_min", -0.5);
  b.set("ground_max", 0.4);
  b.set("window_full", 11);
  b.set("window_half", 5);
  b.set("aggregation", "best_k");
  b.set("best_k", 3);
  b.set("subpixel", false);
  b.set("resolution", "half");
  b.set("crop_width", 0.5);
  b.set("crop_height", 0.75);
  b.set("min_parallax_px", 0.5);
  b.set("min_parallax_ratio", 0.4);
  b.set("min_overlap", 0.3);
  b.set("backend", "cpu");
  b.set("device", "pocl");
  b.set("filter_texture", false);
  b.set("min_texture_snr", 2.0);
  b.set("min_noise_std", 0.01);
  b.set("filter_cost", false);
  b.set("alpha_upper", 0.1);
  b.set("alpha_lower", 0.4);
  b.set("split_row", 0.6);
  b.set("filter_uniqueness", false);
  b.set("max_ratio", 0.8);
  b.set("filter_consistency", false);
  b.set("consistency_window", 7);
  b.set("gamma", 0.7);
  b.set("delta", 0.4);
  const fm::PlaneSweepConfig c = fm::PlaneSweepConfig::fromParams(b.map);
  EXPECT_EQ(c.fronto_planes, 32);
  EXPECT_DOUBLE_EQ(c.near, 2.0);
  EXPECT_DOUBLE_EQ(c.far, 50.0);
  EXPECT_EQ(c.ground_planes, 10);
  EXPECT_DOUBLE_EQ(c.ground_min, -0.5);
  EXPECT_DOUBLE_EQ(c.ground_max, 0.4);
  EXPECT_EQ(c.window_full, 11);
  EXPECT_EQ(c.window_half, 5);
  EXPECT_EQ(c.aggregation, fm::SweepAggregation::BestK);
  EXPECT_EQ(c.best_k, 3);
  EXPECT_FALSE(c.subpixel);
  EXPECT_EQ(c.resolution, fm::SweepResolution::Half);
  EXPECT_DOUBLE_EQ(c.crop_width, 0.5);
  EXPECT_DOUBLE_EQ(c.crop_height, 0.75);
  EXPECT_DOUBLE_EQ(c.min_parallax_px, 0.5);
  EXPECT_DOUBLE_EQ(c.min_parallax_ratio, 0.4);
  EXPECT_DOUBLE_EQ(c.min_overlap, 0.3);
  EXPECT_EQ(c.backend, fm::SweepBackendType::Cpu);
  EXPECT_EQ(c.device, "pocl");
  const fm::DepthFilterConfig& f = c.filters;
  EXPECT_FALSE(f.texture);
  EXPECT_DOUBLE_EQ(f.min_texture_snr, 2.0);
  EXPECT_DOUBLE_EQ(f.min_noise_std, 0.01);
  EXPECT_FALSE(f.cost);
  EXPECT_DOUBLE_EQ(f.alpha_upper, 0.1);
  EXPECT_DOUBLE_EQ(f.alpha_lower, 0.4);
  EXPECT_DOUBLE_EQ(f.split_row, 0.6);
  EXPECT_FALSE(f.uniqueness);
  EXPECT_DOUBLE_EQ(f.max_ratio, 0.8);
  EXPECT_FALSE(f.consistency);
  EXPECT_EQ(f.consistency_window, 7);
  EXPECT_DOUBLE_EQ(f.gamma, 0.7);
  EXPECT_DOUBLE_EQ(f.delta, 0.4);
  // A YAML map with the same values reads the same.
  EXPECT_EQ(describe(fm::PlaneSweepConfig::fromParams(b.yamlParams())), describe(c));
  // Integers where numbers are asked for are numbers (YAML "far: 50").
  fm::MapParams ints;
  ints.set("far", 50);
  EXPECT_DOUBLE_EQ(fm::PlaneSweepConfig::fromParams(ints).far, 50.0);
  EXPECT_DOUBLE_EQ(fm::PlaneSweepConfig::fromParams(fm::YamlParams(YAML::Load("far: 50"))).far, 50.0);
}

TEST(PlaneSweepParams, WrongTypesAreRejectedNamingTheKey) {
  expectWrongTypesRejected<fm::PlaneSweepConfig>(kSweepParams);
}

TEST(PlaneSweepParams, OutOfRangeValuesAreRejectedNamingTheField) {
  const std::vector<std::pair<std::string, double>> numbers = {
      {"near", -1.0},           {"near", 0.0},          {"far", 1.0},          {"ground_max", -0.5},
      {"crop_width", 0.0},      {"crop_height", 1.5},   {"min_parallax_px", -1.0}, {"min_parallax_ratio", 2.0},
      {"min_overlap", -0.1},    {"min_texture_snr", -1.0}, {"min_noise_std", 0.0}, {"alpha_upper", 2.0},
      {"alpha_lower", -1.0},    {"split_row", 2.0},     {"max_ratio", 0.0},    {"gamma", 0.0},
      {"delta", 2.0},
  };
  for (const auto& [k, v] : numbers) {
    fm::MapParams m;
    m.set(k, v);
    expectInvalid([&] { (void)fm::PlaneSweepConfig::fromParams(m); }, {k + ":"}, k + " = " + std::to_string(v));
  }
  const std::vector<std::pair<std::string, int>> ints = {
      {"fronto_planes", 1}, {"ground_planes", 1}, {"window_full", 8}, {"window_half", 1},
      {"best_k", 0},        {"consistency_window", 4},
  };
  for (const auto& [k, v] : ints) {
    fm::MapParams m;
    m.set(k, v);
    expectInvalid([&] { (void)fm::PlaneSweepConfig::fromParams(m); }, {k + ":"}, k + " = " + std::to_string(v));
  }
  fm::MapParams no_ground;
  no_ground.set("ground_planes", 0);  // 0 disables the family
  EXPECT_EQ(fm::PlaneSweepConfig::fromParams(no_ground).ground_planes, 0);
  // The filter fields are named as fields of the config.
  fm::MapParams delta;
  delta.set("delta", 2.0);
  expectInvalid([&] { (void)fm::PlaneSweepConfig::fromParams(delta); }, {"filters.delta:"}, "delta");
}

TEST(PlaneSweepParams, EnumerationsRoundTripAndRejectUnknownNames) {
  for (auto a : {fm::SweepAggregation::Average, fm::SweepAggregation::BestK})
    EXPECT_EQ(fm::parseSweepAggregation(fm::toString(a)), a) << fm::toString(a);
  for (auto r : {fm::SweepResolution::Full, fm::SweepResolution::Half, fm::SweepResolution::Multiscale})
    EXPECT_EQ(fm::parseSweepResolution(fm::toString(r)), r) << fm::toString(r);
  for (auto b : {fm::SweepBackendType::Auto, fm::SweepBackendType::Native, fm::SweepBackendType::OpenCl,
                 fm::SweepBackendType::Cpu})
    EXPECT_EQ(fm::parseSweepBackend(fm::toString(b)), b) << fm::toString(b);
  EXPECT_EQ(fm::toString(fm::SweepAggregation::BestK), "best_k");
  EXPECT_EQ(fm::toString(fm::SweepResolution::Multiscale), "multiscale");
  EXPECT_EQ(fm::toString(fm::SweepBackendType::OpenCl), "opencl");
  // Unknown names: the parameter, the allowed values and the bad one.
  expectInvalid([] { fm::parseSweepAggregation("median"); }, {"aggregation:", "'average'", "'best_k'", "'median'"},
                "aggregation");
  expectInvalid([] { fm::parseSweepResolution("quarter"); },
                {"resolution:", "'full'", "'half'", "'multiscale'", "'quarter'"}, "resolution");
  expectInvalid([] { fm::parseSweepBackend("gpu"); }, {"backend:", "'auto'", "'native'", "'opencl'", "'cpu'", "'gpu'"},
                "backend");
  expectInvalid([] { fm::parseSweepBackend("CPU"); }, {"backend:", "'CPU'"}, "backend (case)");
  expectInvalid([] { fm::parseSweepResolution(""); }, {"resolution:", "''"}, "resolution (empty)");
  // ... and the same from fromParams.
  for (const auto& [k, v] : std::vector<std::pair<std::string, std::string>>{
           {"aggregation", "median"}, {"resolution", "quarter"}, {"backend", "gpu"}}) {
    fm::MapParams m;
    m.set(k, v);
    expectInvalid([&] { (void)fm::PlaneSweepConfig::fromParams(m); }, {k + ":", "'" + v + "'"}, k);
    const fm::YamlParams y(YAML::Load(k + ": " + v));
    expectInvalid([&] { (void)fm::PlaneSweepConfig::fromParams(y); }, {k + ":", "'" + v + "'"}, "YAML " + k);
  }
}

TEST(PlaneSweepParams, TheShippedYamlUsesOnlyKnownNamesAndIsValid) {
  const std::string path = FM_CONFIG_DIR "/plane_sweep_depth.yaml";
  const YAML::Node node = YAML::LoadFile(path);
  std::set<std::string> known = namesOf(kSweepParams);
  known.insert(kDepthStageNames.begin(), kDepthStageNames.end());
  EXPECT_EQ(unknownKeys(node, known), std::vector<std::string>()) << path << ": names no stage reads";
  const fm::PlaneSweepConfig c = fm::PlaneSweepConfig::fromParams(fm::YamlParams(node, path));
  // It states the defaults (to the digits it shows).
  const fm::PlaneSweepConfig d;
  EXPECT_EQ(c.fronto_planes, d.fronto_planes);
  EXPECT_EQ(c.resolution, d.resolution);
  EXPECT_EQ(c.aggregation, d.aggregation);
  EXPECT_EQ(c.backend, d.backend);
  EXPECT_NEAR(c.crop_width, d.crop_width, 1e-4);
  EXPECT_NEAR(c.filters.min_noise_std, d.filters.min_noise_std, 1e-4);
  // vehicle.yaml's plane_sweep section too.
  const YAML::Node vehicle = YAML::LoadFile(FM_CONFIG_DIR "/vehicle.yaml");
  EXPECT_EQ(unknownKeys(vehicle["plane_sweep"], known), std::vector<std::string>()) << "vehicle.yaml plane_sweep";
  EXPECT_NO_THROW(fm::PlaneSweepConfig::fromParams(fm::YamlParams(vehicle["plane_sweep"])));
}

// ---------------------------------------------------------------------------
// DetectorStageConfig

TEST(DetectorParams, EmptyParamsGiveTheDocumentedDefaults) {
  const fm::DetectorStageConfig c = fm::DetectorStageConfig::fromParams(fm::MapParams());
  EXPECT_EQ(c.model_config, "");
  EXPECT_FALSE(c.score_threshold.has_value());  // the model YAML's
  EXPECT_FALSE(c.nms_threshold.has_value());
  EXPECT_EQ(c.dnn_backend, fm::DnnBackend::OpenCv);
  EXPECT_EQ(c.dnn_target, fm::DnnTarget::Cpu);
  EXPECT_TRUE(c.only_moving);
  EXPECT_TRUE(c.publish_annotated);
  EXPECT_EQ(c.device().backend, "opencv");
  EXPECT_EQ(c.device().target, "cpu");
  EXPECT_EQ(describe(c), describe(fm::DetectorStageConfig()));
}

TEST(DetectorParams, ReadsExactlyTheDocumentedNames) {
  EXPECT_EQ(keysRead<fm::DetectorStageConfig>(), namesOf(kDetectorParams));
}

TEST(DetectorParams, EveryParameterIsRead) {
  Both b;
  b.set("model_config", "/models/yolo.yaml");
  b.set("score_threshold", 0.6);
  b.set("nms_threshold", 0.4);
  b.set("dnn_backend", "default");
  b.set("dnn_target", "opencl_fp16");
  b.set("only_moving", false);
  b.set("publish_annotated", false);
  const fm::DetectorStageConfig c = fm::DetectorStageConfig::fromParams(b.map);
  EXPECT_EQ(c.model_config, "/models/yolo.yaml");
  ASSERT_TRUE(c.score_threshold.has_value());
  EXPECT_FLOAT_EQ(*c.score_threshold, 0.6f);
  ASSERT_TRUE(c.nms_threshold.has_value());
  EXPECT_FLOAT_EQ(*c.nms_threshold, 0.4f);
  EXPECT_EQ(c.dnn_backend, fm::DnnBackend::Default);
  EXPECT_EQ(c.dnn_target, fm::DnnTarget::OpenClFp16);
  EXPECT_FALSE(c.only_moving);
  EXPECT_FALSE(c.publish_annotated);
  EXPECT_EQ(c.device().backend, "default");
  EXPECT_EQ(c.device().target, "opencl_fp16");
  EXPECT_EQ(describe(fm::DetectorStageConfig::fromParams(b.yamlParams())), describe(c));
  fm::MapParams ints;  // "nms_threshold: 1" in YAML is an int
  ints.set("nms_threshold", 1);
  EXPECT_FLOAT_EQ(*fm::DetectorStageConfig::fromParams(ints).nms_threshold, 1.0f);
}

TEST(DetectorParams, WrongTypesAreRejectedNamingTheKey) {
  expectWrongTypesRejected<fm::DetectorStageConfig>(kDetectorParams);
}

TEST(DetectorParams, OutOfRangeThresholdsAreRejectedNamingTheFieldAndValue) {
  const std::vector<std::pair<std::string, double>> bad = {
      {"score_threshold", 0.0}, {"score_threshold", -0.1}, {"score_threshold", 1.0}, {"score_threshold", 1.5},
      {"nms_threshold", 0.0},   {"nms_threshold", 1.5},    {"score_threshold", std::nan("")}};
  for (const auto& [k, v] : bad) {
    fm::MapParams m;
    m.set(k, v);
    std::ostringstream value;
    value << float(v);
    expectInvalid([&] { (void)fm::DetectorStageConfig::fromParams(m); }, {k + ":", "got " + value.str()},
                  k + " = " + value.str());
  }
  fm::MapParams edge;
  edge.set("nms_threshold", 1.0);  // (0, 1]
  edge.set("score_threshold", 0.01);
  EXPECT_NO_THROW(fm::DetectorStageConfig::fromParams(edge));
  // validate() on a config set in code.
  fm::DetectorStageConfig c;
  c.nms_threshold = 2.0f;
  expectInvalid([&] { c.validate(); }, {"nms_threshold:", "got 2"}, "validate");
}

TEST(DetectorParams, EnumerationsRoundTripAndRejectUnknownNames) {
  for (auto b : {fm::DnnBackend::OpenCv, fm::DnnBackend::Default})
    EXPECT_EQ(fm::parseDnnBackend(fm::toString(b)), b) << fm::toString(b);
  for (auto t : {fm::DnnTarget::Cpu, fm::DnnTarget::OpenCl, fm::DnnTarget::OpenClFp16})
    EXPECT_EQ(fm::parseDnnTarget(fm::toString(t)), t) << fm::toString(t);
  expectInvalid([] { fm::parseDnnBackend("cuda"); }, {"dnn_backend:", "'opencv'", "'default'", "'cuda'"},
                "dnn_backend");
  expectInvalid([] { fm::parseDnnTarget("gpu"); }, {"dnn_target:", "'cpu'", "'opencl'", "'opencl_fp16'", "'gpu'"},
                "dnn_target");
  fm::MapParams m;
  m.set("dnn_target", "vulkan");
  expectInvalid([&] { (void)fm::DetectorStageConfig::fromParams(m); }, {"dnn_target:", "'vulkan'"}, "fromParams");
}

TEST(DetectorParams, LoadModelAppliesTheOverridesAndModelYamlsCheckTheirThresholds) {
  fm::DetectorStageConfig none;
  EXPECT_THROW(none.loadModel(), std::runtime_error);
  const std::string dir = ::testing::TempDir() + "/test_params_detector";
  std::filesystem::create_directories(dir);
  const std::string base =
      "format: onnx\nmodel: m.onnx\ninput_size: [64, 64]\nhead: yolov8\nclass_names: [car]\nmoving_classes: [car]\n";
  const std::string model = dir + "/thresholds.yaml";
  std::ofstream(model) << base << "score_threshold: 0.3\nnms_threshold: 0.5\n";
  fm::DetectorStageConfig c;
  c.model_config = model;
  const fm::DetectorConfig plain = c.loadModel(), direct = fm::loadDetectorConfig(model);
  EXPECT_FLOAT_EQ(plain.score_threshold, 0.3f);
  EXPECT_FLOAT_EQ(direct.score_threshold, 0.3f);
  EXPECT_FLOAT_EQ(plain.nms_threshold, 0.5f);
  c.score_threshold = 0.61f;
  c.nms_threshold = 0.42f;
  const fm::DetectorConfig over = c.loadModel();
  EXPECT_FLOAT_EQ(over.score_threshold, 0.61f);
  EXPECT_FLOAT_EQ(over.nms_threshold, 0.42f);
  EXPECT_EQ(over.class_names, direct.class_names);
  c.score_threshold = 1.5f;
  EXPECT_THROW(c.loadModel(), std::invalid_argument);
  // A model YAML with out-of-range thresholds: the file, the key and the value.
  for (const auto& [extra, key, value] : {std::make_tuple("nms_threshold: 0\n", "nms_threshold", "got 0"),
                                          std::make_tuple("nms_threshold: 1.5\n", "nms_threshold", "got 1.5"),
                                          std::make_tuple("score_threshold: 1\n", "score_threshold", "got 1"),
                                          std::make_tuple("score_threshold: -0.2\n", "score_threshold", "got -0.2")}) {
    const std::string p = dir + "/model.yaml";
    std::ofstream(p) << base << extra;
    try {
      fm::loadDetectorConfig(p);
      ADD_FAILURE() << "no error for " << extra;
    } catch (const std::runtime_error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(p), std::string::npos) << msg;
      EXPECT_NE(msg.find(std::string("'") + key + "'"), std::string::npos) << msg;
      EXPECT_NE(msg.find(value), std::string::npos) << msg;
    }
  }
  std::ofstream(dir + "/model.yaml") << base << "score_threshold: 0.2\nnms_threshold: 1\n";
  EXPECT_NO_THROW(fm::loadDetectorConfig(dir + "/model.yaml"));
}

// ---------------------------------------------------------------------------
// DepthMaskConfig

TEST(DepthMaskParams, EmptyParamsGiveTheDocumentedDefaults) {
  const fm::DepthMaskConfig c = fm::DepthMaskConfig::fromParams(fm::MapParams());
  EXPECT_DOUBLE_EQ(c.margin_px, 10.0);
  EXPECT_DOUBLE_EQ(c.wait_for_detections, 0.5);
  EXPECT_EQ(c.max_pending, 30);
  EXPECT_DOUBLE_EQ(c.time_reset_threshold, 1.0);
  EXPECT_DOUBLE_EQ(c.colour_near, 1.0);
  EXPECT_DOUBLE_EQ(c.colour_far, 30.0);
  EXPECT_EQ(describe(c), describe(fm::DepthMaskConfig()));
}

TEST(DepthMaskParams, ReadsExactlyTheDocumentedNames) {
  EXPECT_EQ(keysRead<fm::DepthMaskConfig>(), namesOf(kMaskParams));
}

TEST(DepthMaskParams, EveryParameterIsRead) {
  Both b;
  b.set("margin_px", 4.0);
  b.set("wait_for_detections", 0.2);
  b.set("max_pending", 5);
  b.set("time_reset_threshold", 0.0);  // never
  const fm::DepthMaskConfig c = fm::DepthMaskConfig::fromParams(b.map);
  EXPECT_DOUBLE_EQ(c.margin_px, 4.0);
  EXPECT_DOUBLE_EQ(c.wait_for_detections, 0.2);
  EXPECT_EQ(c.max_pending, 5);
  EXPECT_DOUBLE_EQ(c.time_reset_threshold, 0.0);
  EXPECT_EQ(describe(fm::DepthMaskConfig::fromParams(b.yamlParams())), describe(c));
  // colour_range is a list (YAML; MapParams holds no lists).
  b.yaml << "colour_range: [2.0, 20]\n";
  const fm::DepthMaskConfig y = fm::DepthMaskConfig::fromParams(b.yamlParams());
  EXPECT_DOUBLE_EQ(y.colour_near, 2.0);
  EXPECT_DOUBLE_EQ(y.colour_far, 20.0);
  EXPECT_DOUBLE_EQ(y.margin_px, 4.0);
  fm::MapParams ints;  // "margin_px: 10" (vehicle.yaml) is an int
  ints.set("margin_px", 12);
  EXPECT_DOUBLE_EQ(fm::DepthMaskConfig::fromParams(ints).margin_px, 12.0);
}

TEST(DepthMaskParams, WrongTypesAreRejectedNamingTheKey) {
  expectWrongTypesRejected<fm::DepthMaskConfig>(kMaskParams);
}

TEST(DepthMaskParams, OutOfRangeValuesAreRejectedNamingTheFieldAndValue) {
  const std::vector<std::pair<std::string, double>> bad = {
      {"margin_px", -1.0}, {"wait_for_detections", -0.1}, {"time_reset_threshold", std::nan("")},
      {"margin_px", std::numeric_limits<double>::infinity()}};
  for (const auto& [k, v] : bad) {
    fm::MapParams m;
    m.set(k, v);
    std::ostringstream value;
    value << v;
    expectInvalid([&] { (void)fm::DepthMaskConfig::fromParams(m); }, {k + ":", "got " + value.str()},
                  k + " = " + value.str());
  }
  fm::MapParams pending;
  pending.set("max_pending", 0);
  expectInvalid([&] { (void)fm::DepthMaskConfig::fromParams(pending); }, {"max_pending:", "got 0"}, "max_pending");
  for (const auto& [yaml, got] : {std::make_pair("colour_range: [0, 10]", "got 0"),
                                  std::make_pair("colour_range: [5, 3]", "got 3"),
                                  std::make_pair("colour_range: [1, 2, 3]", "got 3"),
                                  std::make_pair("colour_range: []", "got 0")}) {
    const fm::YamlParams y(YAML::Load(yaml));
    expectInvalid([&] { (void)fm::DepthMaskConfig::fromParams(y); }, {"colour_range:", got}, yaml);
  }
  fm::MapParams ok;
  ok.set("margin_px", 0.0);
  ok.set("wait_for_detections", 0.0);
  ok.set("time_reset_threshold", -1.0);  // <= 0: never reset
  EXPECT_NO_THROW(fm::DepthMaskConfig::fromParams(ok));
}

// ---------------------------------------------------------------------------
// FrameSyncConfig

TEST(FrameSyncParams, EmptyParamsGiveTheDocumentedDefaults) {
  const fm::FrameSyncConfig c = fm::FrameSyncConfig::fromParams(fm::MapParams());
  EXPECT_EQ(c.policy, fm::SyncPolicy::Exact);
  EXPECT_DOUBLE_EQ(c.max_interval, 0.005);
  EXPECT_EQ(c.queue_size, 10);
  EXPECT_DOUBLE_EQ(c.silent_warning, 2.0);
  EXPECT_DOUBLE_EQ(c.time_reset_threshold, 1.0);
  EXPECT_TRUE(c.image_topics.empty());  // the camchain's rostopics
  EXPECT_EQ(describe(c), describe(fm::FrameSyncConfig()));
}

TEST(FrameSyncParams, ReadsExactlyTheDocumentedNames) {
  EXPECT_EQ(keysRead<fm::FrameSyncConfig>(), namesOf(kSyncParams));
}

TEST(FrameSyncParams, EveryParameterIsRead) {
  Both b;
  b.set("policy", "approximate");
  b.set("max_interval", 0.02);
  b.set("queue_size", 4);
  b.set("silent_warning", 5.0);
  b.set("time_reset_threshold", 0.5);
  const fm::FrameSyncConfig c = fm::FrameSyncConfig::fromParams(b.map);
  EXPECT_EQ(c.policy, fm::SyncPolicy::Approximate);
  EXPECT_DOUBLE_EQ(c.max_interval, 0.02);
  EXPECT_EQ(c.queue_size, 4);
  EXPECT_DOUBLE_EQ(c.silent_warning, 5.0);
  EXPECT_DOUBLE_EQ(c.time_reset_threshold, 0.5);
  EXPECT_EQ(describe(fm::FrameSyncConfig::fromParams(b.yamlParams())), describe(c));
  b.yaml << "image_topics: [/cam0/image_raw, /cam1/image_raw]\n";
  const fm::FrameSyncConfig y = fm::FrameSyncConfig::fromParams(b.yamlParams());
  EXPECT_EQ(y.image_topics, (std::vector<std::string>{"/cam0/image_raw", "/cam1/image_raw"}));
  EXPECT_EQ(y.queue_size, 4);
}

TEST(FrameSyncParams, WrongTypesAreRejectedNamingTheKey) {
  expectWrongTypesRejected<fm::FrameSyncConfig>(kSyncParams);
}

TEST(FrameSyncParams, OutOfRangeValuesAreRejectedNamingTheFieldAndValue) {
  const std::vector<std::pair<std::string, double>> bad = {
      {"max_interval", -0.001}, {"silent_warning", 0.0}, {"silent_warning", -2.0},
      {"time_reset_threshold", std::nan("")}};
  for (const auto& [k, v] : bad) {
    fm::MapParams m;
    m.set(k, v);
    std::ostringstream value;
    value << v;
    expectInvalid([&] { (void)fm::FrameSyncConfig::fromParams(m); }, {k + ":", "got " + value.str()},
                  k + " = " + value.str());
  }
  fm::MapParams queue;
  queue.set("queue_size", 0);
  expectInvalid([&] { (void)fm::FrameSyncConfig::fromParams(queue); }, {"queue_size:", "got 0"}, "queue_size");
  const fm::YamlParams empty_topic(YAML::Load("image_topics: [/cam0/image_raw, '']"));
  expectInvalid([&] { (void)fm::FrameSyncConfig::fromParams(empty_topic); }, {"image_topics:", "1"}, "image_topics");
  fm::MapParams ok;
  ok.set("max_interval", 0.0);
  ok.set("time_reset_threshold", 0.0);  // never reset
  EXPECT_NO_THROW(fm::FrameSyncConfig::fromParams(ok));
}

TEST(FrameSyncParams, PolicyRoundTripsAndRejectsUnknownNames) {
  for (auto p : {fm::SyncPolicy::Exact, fm::SyncPolicy::Approximate})
    EXPECT_EQ(fm::parseSyncPolicy(fm::toString(p)), p) << fm::toString(p);
  expectInvalid([] { fm::parseSyncPolicy("nearest"); }, {"policy:", "'exact'", "'approximate'", "'nearest'"},
                "policy");
  fm::MapParams m;
  m.set("policy", "Exact");
  expectInvalid([&] { (void)fm::FrameSyncConfig::fromParams(m); }, {"policy:", "'Exact'"}, "fromParams");
}

// ---------------------------------------------------------------------------
// config/vehicle.yaml: each stage's section uses only names the stage reads.

TEST(StageParams, VehicleYamlSectionsUseOnlyKnownNames) {
  const YAML::Node v = YAML::LoadFile(FM_CONFIG_DIR "/vehicle.yaml");
  std::set<std::string> sync = namesOf(kSyncParams), detector = namesOf(kDetectorParams),
                        mask = namesOf(kMaskParams);
  sync.insert(kSyncRosNames.begin(), kSyncRosNames.end());
  detector.insert(kDetectorRosNames.begin(), kDetectorRosNames.end());
  EXPECT_EQ(join(unknownKeys(v["sync"], sync)), "") << "vehicle.yaml sync";
  EXPECT_EQ(join(unknownKeys(v["detector"], detector)), "") << "vehicle.yaml detector";
  EXPECT_EQ(join(unknownKeys(v["depth_mask"], mask)), "") << "vehicle.yaml depth_mask";
  EXPECT_NO_THROW(fm::FrameSyncConfig::fromParams(fm::YamlParams(v["sync"])));
  EXPECT_NO_THROW(fm::DetectorStageConfig::fromParams(fm::YamlParams(v["detector"])));
  EXPECT_NO_THROW(fm::DepthMaskConfig::fromParams(fm::YamlParams(v["depth_mask"])));
}
