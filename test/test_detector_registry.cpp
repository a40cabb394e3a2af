// The detector registry (core/detection/detector_registry.h): each name's
// model YAML, written out here by hand from config/detector/ and the cache
// layout scripts/tools/train_vehicle_detector writes; unknown names; paths of
// one's own; the cache variables' precedence.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <stdexcept>
#include <string>

#include "fisheye_mapping/core/detection/detector_registry.h"

namespace fm = fisheye_mapping;

namespace {

const std::string kConfig = FM_CONFIG_DIR;

// Sets (or, with nullopt, unsets) an environment variable for the scope.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const std::optional<std::string>& value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    if (value) setenv(name, value->c_str(), 1);
    else unsetenv(name);
  }
  ~ScopedEnv() {
    if (old_) setenv(name_, old_->c_str(), 1);
    else unsetenv(name_);
  }

 private:
  const char* name_;
  std::optional<std::string> old_;
};

// The message of the exception `f` throws as E ("" when it throws none).
template <class E, class F>
std::string thrown(F f) {
  try {
    f();
  } catch (const E& e) {
    return e.what();
  }
  return "";
}

TEST(DetectorRegistry, NamesGiveTheModelsOfTheTree) {
  EXPECT_EQ(fm::detectorModelPath("nanodet", kConfig), kConfig + "/detector/nanodet.yaml");
  EXPECT_EQ(fm::detectorModelPath("darknet", kConfig), kConfig + "/detector/yolov3-tiny.yaml");
  EXPECT_EQ(fm::detectorModelPath("yolov3-tiny", kConfig), kConfig + "/detector/yolov3-tiny.yaml");
  EXPECT_EQ(fm::detectorModelPath("yolov3", kConfig), kConfig + "/detector/yolov3.yaml");
  EXPECT_EQ(fm::detectorModelPath("yolov4-tiny", kConfig), kConfig + "/detector/yolov4-tiny.yaml");
  EXPECT_EQ(fm::detectorModelPath("yolov8n", kConfig), kConfig + "/detector/yolov8n.yaml");
  EXPECT_EQ(fm::knownDetectorNames(), "nanodet, finetuned, darknet, yolov3-tiny, yolov3, yolov4-tiny, yolov8n");
  // Every model YAML of config/detector/ has a name.
  for (const auto& f : std::filesystem::directory_iterator(kConfig + "/detector")) {
    const std::string stem = f.path().stem().string();
    EXPECT_EQ(fm::detectorModelPath(stem, kConfig), f.path().string()) << stem;
  }
}

TEST(DetectorRegistry, AnUnknownNameListsTheKnownOnes) {
  EXPECT_EQ(thrown<std::invalid_argument>([] { fm::detectorModelPath("yolo", kConfig); }),
            "unknown detector 'yolo' (known: nanodet, finetuned, darknet, yolov3-tiny, yolov3, yolov4-tiny, yolov8n; "
            "or the path of a model YAML)");
  EXPECT_NE(thrown<std::invalid_argument>([] { fm::detectorModelPath("", kConfig); }), "");
  EXPECT_NE(thrown<std::invalid_argument>([] { fm::detectorModelPath("NanoDet", kConfig); }), "");
  // A config folder without the model: the file is named.
  EXPECT_EQ(thrown<std::runtime_error>([] { fm::detectorModelPath("nanodet", "/nonexistent"); }),
            "nanodet: /nonexistent/detector/nanodet.yaml does not exist");
}

TEST(DetectorRegistry, APathIsAModelOfOnesOwn) {
  const std::string own = kConfig + "/rig/default_mount.yaml";  // any existing file
  EXPECT_EQ(fm::detectorModelPath(own, kConfig), own);
  EXPECT_EQ(thrown<std::runtime_error>([] { fm::detectorModelPath("/nonexistent/model.yaml", kConfig); }),
            "/nonexistent/model.yaml does not exist");
  EXPECT_EQ(thrown<std::runtime_error>([] { fm::detectorModelPath("mine.yaml", kConfig); }),
            "mine.yaml does not exist");
}

TEST(DetectorRegistry, TheCacheFollowsTheVariablesInOrder) {
  ScopedEnv home("HOME", std::string("/h"));
  {
    ScopedEnv a("FISHEYE_MAPPING_CACHE", std::string("/a")), b("XDG_CACHE_HOME", std::string("/b"));
    EXPECT_EQ(fm::cacheDir(), "/a");
    EXPECT_EQ(fm::finetunedModelPath(), "/a/models/finetuned/nanodet-fisheye.yaml");
  }
  {
    ScopedEnv a("FISHEYE_MAPPING_CACHE", std::nullopt), b("XDG_CACHE_HOME", std::string("/b"));
    EXPECT_EQ(fm::finetunedModelPath(), "/b/fisheye_mapping/models/finetuned/nanodet-fisheye.yaml");
  }
  {
    ScopedEnv a("FISHEYE_MAPPING_CACHE", std::string("")), b("XDG_CACHE_HOME", std::nullopt);
    EXPECT_EQ(fm::finetunedModelPath(), "/h/.cache/fisheye_mapping/models/finetuned/nanodet-fisheye.yaml");
  }
}

TEST(DetectorRegistry, FinetunedIsTheCachesModelOnceMade) {
  const std::string cache = ::testing::TempDir() + "/fm_registry_cache";
  std::filesystem::remove_all(cache);
  ScopedEnv a("FISHEYE_MAPPING_CACHE", cache);
  const std::string yaml = cache + "/models/finetuned/nanodet-fisheye.yaml";
  EXPECT_EQ(thrown<std::runtime_error>([] { fm::detectorModelPath("finetuned", kConfig); }),
            "finetuned: " + yaml + " does not exist (make it with scripts/tools/train_vehicle_detector)");
  std::filesystem::create_directories(cache + "/models/finetuned");
  std::ofstream(yaml) << "model: nanodet-fisheye.onnx\n";
  EXPECT_EQ(fm::detectorModelPath("finetuned", kConfig), yaml);
  std::filesystem::remove_all(cache);
}

}  // namespace
