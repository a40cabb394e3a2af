// The detector registry: the one place that maps a detector's name
// (offline_mapper --detector, vehicle.launch / dynamic_objects.launch
// detector:=) to its model YAML. The launch files ask it through the
// detector_model tool; offline_mapper calls it directly.
//
//   nanodet      config/detector/nanodet.yaml (COCO NanoDet, made by scripts/setup)
//   finetuned    <cache>/models/finetuned/nanodet-fisheye.yaml (made by
//                scripts/tools/train_vehicle_detector)
//   darknet      config/detector/yolov3-tiny.yaml (the official weights, see the YAML)
//   yolov3-tiny, yolov3, yolov4-tiny, yolov8n
//                config/detector/<name>.yaml
//
// <cache> is $FISHEYE_MAPPING_CACHE, else $XDG_CACHE_HOME/fisheye_mapping, else
// $HOME/.cache/fisheye_mapping (a variable set but empty counts as unset).
// ground_truth (the drive's true boxes) and none are not models: the callers
// handle them.
#ifndef FISHEYE_MAPPING_CORE_DETECTION_DETECTOR_REGISTRY_H_
#define FISHEYE_MAPPING_CORE_DETECTION_DETECTOR_REGISTRY_H_

#include <string>
#include <vector>

namespace fisheye_mapping {

struct DetectorEntry {
  std::string name;
  std::string description;
};

/// Every detector name, in the order of the table above.
const std::vector<DetectorEntry>& knownDetectors();

/// "nanodet, finetuned, darknet, ...": the names, for messages and usages.
std::string knownDetectorNames();

/// The project's cache folder (see above).
std::string cacheDir();

/// The fine-tuned model's YAML: cacheDir() + "/models/finetuned/nanodet-fisheye.yaml".
std::string finetunedModelPath();

/// The model YAML of `detector`: a registry name's (in-tree models under
/// `config_dir`, the package's config/), or `detector` itself when it is a
/// path (contains '/' or ends in .yaml: a model of one's own). The file must
/// exist. Throws std::invalid_argument for an unknown name ("unknown detector
/// 'x' (known: ...)"), and std::runtime_error when the file is missing:
/// "finetuned: PATH does not exist (make it with ...)" for a name,
/// "PATH does not exist" for a path.
std::string detectorModelPath(const std::string& detector, const std::string& config_dir);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_DETECTION_DETECTOR_REGISTRY_H_
