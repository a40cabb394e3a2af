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
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--config" && i + 1 < argc) config = argv[++i];
    else if (a == "--out-dir" && i + 1 < argc) out_dir = argv[++i];
    else if (a == "--all-classes") all = true;
    else if (a == "--grey") grey = true;
    else if (a == "--config" || a == "--out-dir") {
      std::cerr << "detect_image: " << a << " needs a value\n";
      return 2;
    } else if (!a.empty() && a[0] == '-') {
      std::cerr << "usage: detect_image --config YAML [--all-classes] [--grey] [--out-dir DIR] IMAGE...\n";
      return 2;
    } else images.push_back(a);
  }
  if (config.empty() || images.empty()) {
    std::cerr << "detect_image: --config and at least one image are required\n";
    return 2;
  }
  try {
    cli::requireInputFile("--config", config);
    if (!out_dir.empty()) {
      std::error_code ec;
      if (!std::filesystem::is_directory(out_dir, ec)) throw cli::UsageError("--out-dir: " + out_dir + ": no such folder");
    }
  } catch (const cli::UsageError& e) {
    std::cerr << "detect_image: " << e.what() << "\n";
    return 2;
  }
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
