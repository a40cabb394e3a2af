#include "fisheye_mapping/core/detection/detector_registry.h"

#include <cstdlib>
#include <filesystem>
#include <stdexcept>

namespace fisheye_mapping {

namespace {

constexpr const char* kFinetuned = "finetuned";

// An in-tree model's file under config/detector/ (empty for finetuned).
struct Model {
  DetectorEntry entry;
  std::string file;
};

const std::vector<Model>& models() {
  static const std::vector<Model> m = {
      {{"nanodet", "COCO NanoDet (scripts/setup)"}, "nanodet.yaml"},
      {{kFinetuned, "NanoDet fine-tuned on grey fisheye frames (scripts/tools/train_vehicle_detector)"}, ""},
      {{"darknet", "Darknet YOLOv3-tiny (bring the official weights)"}, "yolov3-tiny.yaml"},
      {{"yolov3-tiny", "Darknet YOLOv3-tiny"}, "yolov3-tiny.yaml"},
      {{"yolov3", "Darknet YOLOv3"}, "yolov3.yaml"},
      {{"yolov4-tiny", "Darknet YOLOv4-tiny"}, "yolov4-tiny.yaml"},
      {{"yolov8n", "Ultralytics YOLOv8n (ONNX)"}, "yolov8n.yaml"},
  };
  return m;
}

// The variable's value; empty when unset or empty.
std::string env(const char* name) {
  const char* v = std::getenv(name);
  return v ? v : "";
}

// "<what>PATH does not exist<hint>" unless `path` is a file.
void requireFile(const std::string& path, const std::string& what, const std::string& hint = "") {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw std::runtime_error(what + path + " does not exist" + hint);
}

}  // namespace

const std::vector<DetectorEntry>& knownDetectors() {
  static const std::vector<DetectorEntry> e = [] {
    std::vector<DetectorEntry> out;
    for (const Model& m : models()) out.push_back(m.entry);
    return out;
  }();
  return e;
}

std::string knownDetectorNames() {
  std::string s;
  for (const DetectorEntry& e : knownDetectors()) s += (s.empty() ? "" : ", ") + e.name;
  return s;
}

std::string cacheDir() {
  if (!env("FISHEYE_MAPPING_CACHE").empty()) return env("FISHEYE_MAPPING_CACHE");
  if (!env("XDG_CACHE_HOME").empty()) return env("XDG_CACHE_HOME") + "/fisheye_mapping";
  return env("HOME") + "/.cache/fisheye_mapping";
}

std::string finetunedModelPath() { return cacheDir() + "/models/finetuned/nanodet-fisheye.yaml"; }

std::string detectorModelPath(const std::string& detector, const std::string& config_dir) {
  for (const Model& m : models()) {
    if (m.entry.name != detector) continue;
    if (m.file.empty()) {
      const std::string path = finetunedModelPath();
      requireFile(path, "finetuned: ", " (make it with scripts/tools/train_vehicle_detector)");
      return path;
    }
    const std::string path = config_dir + "/detector/" + m.file;
    requireFile(path, detector + ": ");
    return path;
  }
  const bool is_path = detector.find('/') != std::string::npos ||
                       (detector.size() > 5 && detector.compare(detector.size() - 5, 5, ".yaml") == 0);
  if (!is_path) {
    throw std::invalid_argument("unknown detector '" + detector + "' (known: " + knownDetectorNames() +
                                "; or the path of a model YAML)");
  }
  requireFile(detector, "");
  return detector;
}

}  // namespace fisheye_mapping
