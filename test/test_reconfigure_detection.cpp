// The dynamic_reconfigure declarations of the detector and the depth mask
// (cfg/DetectorReconfigure.cfg, cfg/DepthMaskReconfigure.cfg) checked against the one list of
// parameters the core reads (DetectorStageConfig::fromParams,
// DepthMaskConfig::fromParams): the same names (less the start-up-only ones),
// the same defaults, and ranges the core accepts end to end. The nodelets'
// reconfigure callbacks go through ReconfigureParams and the same fromParams,
// so a name or default that drifts in either place fails here. No roscore.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "fisheye_mapping/DepthMaskReconfigureConfig.h"
#include "fisheye_mapping/DetectorReconfigureConfig.h"

#include "fisheye_mapping/core/detection/depth_mask.h"
#include "fisheye_mapping/core/detection/detector.h"
#include "fisheye_mapping/ros/ros_params.h"

namespace fm = fisheye_mapping;

namespace {

using DetectorCfg = fm::DetectorReconfigureConfig;
using DepthMaskCfg = fm::DepthMaskReconfigureConfig;

template <class Cfg>
std::set<std::string> cfgNames() {
  std::set<std::string> names;
  for (const auto& d : Cfg::__getParamDescriptions__()) names.insert(d->name);
  return names;
}

template <class Cfg>
dynamic_reconfigure::Config message(const Cfg& c) {
  dynamic_reconfigure::Config msg;
  c.__toMessage__(msg);
  return msg;
}

fm::DetectorStageConfig detectorFrom(const dynamic_reconfigure::Config& msg) {
  return fm::DetectorStageConfig::fromParams(fm::ReconfigureParams(msg));
}
fm::DepthMaskConfig maskFrom(const dynamic_reconfigure::Config& msg) {
  return fm::DepthMaskConfig::fromParams(fm::ReconfigureParams(msg));
}

bool same(const fm::DetectorStageConfig& a, const fm::DetectorStageConfig& b) {
  return a.model_config == b.model_config && a.score_threshold == b.score_threshold &&
         a.nms_threshold == b.nms_threshold && a.dnn_backend == b.dnn_backend && a.dnn_target == b.dnn_target &&
         a.only_moving == b.only_moving && a.publish_annotated == b.publish_annotated;
}
bool same(const fm::DepthMaskConfig& a, const fm::DepthMaskConfig& b) {
  return a.margin_px == b.margin_px && a.wait_for_detections == b.wait_for_detections &&
         a.max_pending == b.max_pending && a.time_reset_threshold == b.time_reset_threshold &&
         a.colour_near == b.colour_near && a.colour_far == b.colour_far;
}

// Sets the one parameter `name` of `msg` to `v` (of the description's type).
void setValue(dynamic_reconfigure::Config& msg, const std::string& type, const std::string& name, const boost::any& v) {
  if (type == "bool") {
    for (auto& p : msg.bools) if (p.name == name) p.value = boost::any_cast<bool>(v);
  } else if (type == "int") {
    for (auto& p : msg.ints) if (p.name == name) p.value = boost::any_cast<int>(v);
  } else {
    for (auto& p : msg.doubles) if (p.name == name) p.value = boost::any_cast<double>(v);
  }
}

// Each parameter of Cfg at the ends of its range (a switch flipped) is
// accepted by the core's fromParams + validate and, away from the default,
// changes the core config.
template <class Cfg, class Core, class From>
void checkRanges(From from, const Core& at_default) {
  const Cfg def = Cfg::__getDefault__(), lo = Cfg::__getMin__(), hi = Cfg::__getMax__();
  for (const auto& d : Cfg::__getParamDescriptions__()) {
    for (const Cfg* end : {&lo, &hi}) {
      boost::any v, dv;
      d->getValue(*end, v);
      d->getValue(def, dv);
      if (d->type == "bool") v = !boost::any_cast<bool>(dv);
      dynamic_reconfigure::Config msg = message(def);
      setValue(msg, d->type, d->name, v);
      const char* which = end == &lo ? "minimum" : "maximum";
      Core c;
      ASSERT_NO_THROW(c = from(msg)) << d->name << " at the " << which << " of its .cfg range";
      EXPECT_FALSE(same(c, at_default)) << d->name << " at the " << which << " does not reach the core";
    }
  }
}

}  // namespace

// Every reconfigurable name is a parameter the core reads; what the core reads
// and the .cfg lacks is exactly the start-up-only set: the model and the DNN
// device (a new network), and for the mask the colour range (a list).
TEST(ReconfigureDetection, CfgNamesAreTheCoreParameters) {
  fm::RecordingParams det;
  fm::DetectorStageConfig::fromParams(det);
  std::set<std::string> core = det.asked();
  for (const char* start_up : {"model_config", "dnn_backend", "dnn_target"}) {
    ASSERT_TRUE(core.count(start_up)) << start_up;
    core.erase(start_up);
  }
  EXPECT_EQ(cfgNames<DetectorCfg>(), core);
  EXPECT_EQ(cfgNames<DetectorCfg>(),
            (std::set<std::string>{"score_threshold", "nms_threshold", "only_moving", "publish_annotated"}));

  fm::RecordingParams mask;
  fm::DepthMaskConfig::fromParams(mask);
  core = mask.asked();
  ASSERT_TRUE(core.count("colour_range"));
  core.erase("colour_range");
  EXPECT_EQ(cfgNames<DepthMaskCfg>(), core);
  EXPECT_EQ(cfgNames<DepthMaskCfg>(),
            (std::set<std::string>{"margin_px", "wait_for_detections", "max_pending", "time_reset_threshold"}));
}

// The .cfg defaults are the core's. The detector's thresholds have no stage
// default (the model YAML's apply): the .cfg's are those of a model YAML
// without the keys (DetectorConfig's).
TEST(ReconfigureDetection, CfgDefaultsAreTheCoreDefaults) {
  const DetectorCfg d = DetectorCfg::__getDefault__();
  const fm::DetectorConfig model;
  fm::DetectorStageConfig expected;
  expected.score_threshold = model.score_threshold;
  expected.nms_threshold = model.nms_threshold;
  const fm::DetectorStageConfig got = detectorFrom(message(d));
  EXPECT_TRUE(same(got, expected));
  EXPECT_FLOAT_EQ(*got.score_threshold, 0.35f);  // detector.h
  EXPECT_FLOAT_EQ(*got.nms_threshold, 0.5f);
  EXPECT_TRUE(d.only_moving);
  EXPECT_TRUE(d.publish_annotated);

  const DepthMaskCfg m = DepthMaskCfg::__getDefault__();
  EXPECT_TRUE(same(maskFrom(message(m)), fm::DepthMaskConfig()));
  // Hand-checked against docs/dynamic_objects.md.
  EXPECT_DOUBLE_EQ(m.margin_px, 10.0);
  EXPECT_DOUBLE_EQ(m.wait_for_detections, 0.5);
  EXPECT_EQ(m.max_pending, 30);
  EXPECT_DOUBLE_EQ(m.time_reset_threshold, 1.0);
}

TEST(ReconfigureDetection, EveryDetectorValueReachesTheCoreAndItsRangeIsValid) {
  fm::DetectorStageConfig at_default = detectorFrom(message(DetectorCfg::__getDefault__()));
  checkRanges<DetectorCfg>(detectorFrom, at_default);
  // The core's own bounds: the .cfg stays inside the open (0, 1) of the score.
  EXPECT_GT(DetectorCfg::__getMin__().score_threshold, 0.0);
  EXPECT_LT(DetectorCfg::__getMax__().score_threshold, 1.0);
  EXPECT_DOUBLE_EQ(DetectorCfg::__getMax__().nms_threshold, 1.0);  // (0, 1]: 1 allowed
}

TEST(ReconfigureDetection, EveryDepthMaskValueReachesTheCoreAndItsRangeIsValid) {
  checkRanges<DepthMaskCfg>(maskFrom, fm::DepthMaskConfig());
  // The core rejects what lies just outside the ranges' closed ends.
  dynamic_reconfigure::Config msg = message(DepthMaskCfg::__getDefault__());
  setValue(msg, "double", "margin_px", boost::any(-0.5));
  EXPECT_THROW(maskFrom(msg), std::invalid_argument);
  msg = message(DepthMaskCfg::__getDefault__());
  setValue(msg, "int", "max_pending", boost::any(0));
  EXPECT_THROW(maskFrom(msg), std::invalid_argument);
}

// A reconfigure overlays the running configuration: what the .cfg lacks
// (the model, the colour range) stays as started.
TEST(ReconfigureDetection, ReconfigureKeepsTheStartUpOnlyParameters) {
  fm::DetectorStageConfig running;
  running.model_config = "/models/x.yaml";
  running.dnn_target = fm::DnnTarget::OpenCl;
  DetectorCfg d = DetectorCfg::__getDefault__();
  d.score_threshold = 0.8;
  const auto det = fm::DetectorStageConfig::fromParams(fm::ReconfigureParams(message(d)), running);
  EXPECT_EQ(det.model_config, "/models/x.yaml");
  EXPECT_EQ(det.dnn_target, fm::DnnTarget::OpenCl);
  EXPECT_FLOAT_EQ(*det.score_threshold, 0.8f);

  fm::DepthMaskConfig mrun;
  mrun.colour_near = 2.0, mrun.colour_far = 50.0;
  DepthMaskCfg m = DepthMaskCfg::__getDefault__();
  m.margin_px = 30;
  const auto mask = fm::DepthMaskConfig::fromParams(fm::ReconfigureParams(message(m)), mrun);
  EXPECT_DOUBLE_EQ(mask.colour_near, 2.0);
  EXPECT_DOUBLE_EQ(mask.colour_far, 50.0);
  EXPECT_DOUBLE_EQ(mask.margin_px, 30.0);
}

// max_pending reconfigured while depth maps wait: the next add releases the
// excess, oldest first, unmasked and marked as a queue overflow (not as a
// wait that ran out); detection sets beyond it are dropped and counted.
TEST(ReconfigureDetection, LowerMaxPendingReleasesTheExcessAsQueueFull) {
  fm::StampPairer<int, int> pairer(10.0, 5);
  for (std::uint64_t s = 1; s <= 4; ++s) EXPECT_TRUE(pairer.addDepth(s, int(s), 0.0).empty());
  pairer.setMaxPending(2);
  const auto out = pairer.addDepth(5, 5, 0.1);  // 5 waiting, 2 allowed: stamps 1, 2, 3 leave
  ASSERT_EQ(out.size(), 3u);
  for (std::size_t i = 0; i < out.size(); ++i) {
    EXPECT_EQ(out[i].stamp, i + 1);
    EXPECT_FALSE(out[i].dets.has_value());
    EXPECT_TRUE(out[i].queue_full);
  }
  EXPECT_EQ(pairer.pendingDepth(), 2u);
  // The wait running out is not a queue overflow.
  const auto timed_out = pairer.poll(10.5);
  ASSERT_EQ(timed_out.size(), 2u);
  EXPECT_FALSE(timed_out[0].queue_full);
  // Detection sets: 3 without depth, 2 kept, the oldest dropped.
  for (std::uint64_t s = 20; s < 23; ++s) pairer.addDetections(s, int(s), 11.0);
  EXPECT_EQ(pairer.pendingDetections(), 2u);
  EXPECT_EQ(pairer.detectionsDropped(), 1u);
}
