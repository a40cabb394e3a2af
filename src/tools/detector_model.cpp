// detector_model: the model YAML of a detector name, from the detector
// registry (core/detection/detector_registry.h), for the launch files:
//
//   <param name="model_config" command="rosrun fisheye_mapping detector_model $(arg detector) ..."/>
//
// prints the path without a newline (the parameter's value); an unknown name
// or a missing model file stops roslaunch with the message on stderr.
#include <iostream>
#include <string>

#include "cli.h"
#include "fisheye_mapping/core/detection/detector_registry.h"

namespace fm = fisheye_mapping;
namespace cli = fm::cli;

namespace {

const std::string kUsage =
    "usage: detector_model DETECTOR [--model YAML] [--finetuned-model YAML] [--config-dir DIR]\n"
    "       detector_model --list\n"
    "  Prints the model YAML of DETECTOR (no newline), for a launch file's <param command=...>.\n"
    "  DETECTOR             a name (" + fm::knownDetectorNames() + ")\n"
    "                       or the path of a model YAML\n"
    "  --model YAML         this model instead, whatever DETECTOR is (empty: none)\n"
    "  --finetuned-model YAML  the model of DETECTOR finetuned (empty: the cache's,\n"
    "                       $FISHEYE_MAPPING_CACHE or $XDG_CACHE_HOME/fisheye_mapping or\n"
    "                       ~/.cache/fisheye_mapping, then models/finetuned/nanodet-fisheye.yaml)\n"
    "  --config-dir DIR     the in-tree models' config folder (default: the package's config/)\n"
    "  --list               every name with its model, one a line\n";

}  // namespace

int main(int argc, char** argv) {
  std::string detector, model, finetuned, config_dir = FM_CONFIG_DIR;
  bool list = false;
  const int rc = cli::parseCommandLine("detector_model", kUsage, [&] {
    cli::forEachOption(argc, argv, 1, [&](const std::string& a, const cli::NextValue& next) {
      if (a == "--model") model = next();
      else if (a == "--finetuned-model") finetuned = next();
      else if (a == "--config-dir") config_dir = next();
      else if (a == "--list") list = true;
      else if (a.empty() || a[0] != '-') {
        if (!detector.empty()) return false;  // a second one: unexpected
        detector = a;
      } else return false;
      return true;
    });
    if (!list && detector.empty()) throw cli::UsageError("missing DETECTOR");
    // Paths of one's own: checked here, not looked up.
    if (!model.empty()) cli::requireInputFile("--model", model);
    if (!finetuned.empty()) cli::requireInputFile("--finetuned-model", finetuned);
  });
  if (rc >= 0) return rc;
  try {
    if (list) {
      for (const fm::DetectorEntry& e : fm::knownDetectors()) std::cout << e.name << "  " << e.description << "\n";
      return 0;
    }
    if (!model.empty()) std::cout << model;
    else if (detector == "finetuned" && !finetuned.empty()) std::cout << finetuned;
    else std::cout << fm::detectorModelPath(detector, config_dir);
    return 0;
  } catch (const std::invalid_argument& e) {  // an unknown name
    std::cerr << "detector_model: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {  // a missing model file
    std::cerr << "detector_model: detector " << e.what() << "\n";
    return 1;
  }
}
