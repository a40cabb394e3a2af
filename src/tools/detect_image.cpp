// detect_image: runs the detector of a model YAML on image files, prints one line
// per detection (file, class, score, box in image pixels) and optionally writes
// the annotated images. The same core Detector as the Detector nodelet.
//
//   detect_image --config YAML [--all-classes] [--grey] [--out-dir DIR] IMAGE...
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "cli.h"
#include "fisheye_mapping/core/detection/detector.h"

namespace fm = fisheye_mapping;
namespace cli = fm::cli;

int main(int argc, char** argv) {
  std::string config, out_dir;
  bool all = false, grey = false;
  std::vector<std::string> images;
  const char* usage =
      "usage: detect_image --config YAML [--all-classes] [--grey] [--out-dir DIR] IMAGE...\n"
      "  --config YAML   the detector model (config/detector/*.yaml)\n"
      "  --all-classes   report every class (default: the config's moving classes only)\n"
      "  --grey          read the images as grey, as the cameras deliver them\n"
      "  --out-dir DIR   write each image with its boxes drawn into DIR (must exist)\n";
  const int rc = cli::parseCommandLine("detect_image", usage, [&] {
    cli::forEachOption(argc, argv, 1, [&](const std::string& a, const cli::NextValue& next) {
      if (a == "--config") config = next();
      else if (a == "--out-dir") out_dir = next();
      else if (a == "--all-classes") all = true;
      else if (a == "--grey") grey = true;
      else if (!a.empty() && a[0] != '-') images.push_back(a);
      else return false;
      return true;
    });
    if (config.empty() || images.empty()) throw cli::UsageError("--config and at least one image are required");
    cli::requireInputFile("--config", config);
    if (!out_dir.empty()) {
      std::error_code ec;
      if (!std::filesystem::is_directory(out_dir, ec)) throw cli::UsageError("--out-dir: " + out_dir + ": no such folder");
    }
  });
  if (rc >= 0) return rc;
  try {
    fm::Detector det(fm::loadDetectorConfig(config));
    int failed = 0;
    for (const auto& path : images) {
      std::error_code ec;
      if (std::filesystem::is_directory(path, ec)) {
        std::cerr << "detect_image: " << path << " is a directory, expected an image file\n";
        ++failed;
        continue;
      }
      cv::Mat img = cv::imread(path, grey ? cv::IMREAD_GRAYSCALE : cv::IMREAD_COLOR);
      if (img.empty()) {
        std::cerr << "detect_image: cannot read " << path << "\n";
        ++failed;
        continue;
      }
      const auto dets = det.detect(img, !all);
      for (const auto& d : dets)
        std::printf("%s %s %.3f %.1f %.1f %.1f %.1f\n", path.c_str(), d.class_name.c_str(), d.score, d.x_min, d.y_min,
                    d.x_max, d.y_max);
      if (!out_dir.empty()) {
        const auto slash = path.find_last_of('/');
        std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
        name = name.substr(0, name.find_last_of('.')) + "_detections.png";
        const std::string target = out_dir + "/" + name;
        try {
          // Written beside the target and renamed: a failed write keeps an earlier file.
          std::vector<uchar> png;
          if (!cv::imencode(".png", fm::annotateDetections(img, dets), png))
            throw std::runtime_error("cannot encode " + target);
          cli::writeTextAtomically(target, [&](std::ostream& f) {
            f.write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
          });
        } catch (const std::exception&) {
          std::cerr << "detect_image: cannot write " << target << "\n";
          ++failed;
        }
      }
    }
    return failed ? 1 : 0;
  } catch (const std::exception& e) {
    std::cerr << "detect_image: " << e.what() << "\n";
    return 1;
  }
}
