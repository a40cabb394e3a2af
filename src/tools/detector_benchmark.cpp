// detector_benchmark: milliseconds per frame of the detector (model YAML) on a
// 1024x544 grey fisheye frame of the default rig's reference camera (rendered
// urban street with vehicles, or --image), for each cv::dnn target asked for.
// Reports the target actually used (OpenCV falls back to the CPU when its
// OpenCL runtime is unavailable) and the detections found.
//
//   detector_benchmark --config YAML --camchain F --mount F
//                      [--image PNG] [--targets cpu,opencl] [--repeats N]
#include <opencv2/core/ocl.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "cli.h"
#include "fisheye_mapping/core/detection/detector.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/sim/synthetic_world.h"

namespace fm = fisheye_mapping;
namespace cli = fm::cli;

int main(int argc, char** argv) {
  std::string config, camchain, mount, image_path, targets = "cpu,opencl";
  int repeats = 20;
  const char* usage =
      "usage: detector_benchmark --config YAML (--camchain F --mount F | --image PNG)\n"
      "                          [--targets cpu,opencl] [--repeats N]\n"
      "  --config YAML         the detector model (config/detector/*.yaml)\n"
      "  --camchain F, --mount F  the rig whose reference camera sees the rendered street\n"
      "  --image PNG           time on this image instead of a rendered frame\n"
      "  --targets LIST        cv::dnn targets, comma-separated, at most 16 (default cpu,opencl)\n"
      "  --repeats N           timed runs per target, 1 to 10000 (default 20)\n";
  const int rc = cli::parseCommandLine("detector_benchmark", usage, [&] {
    cli::forEachOption(argc, argv, 1, [&](const std::string& a, const cli::NextValue& next) {
      if (a == "--config") config = next();
      else if (a == "--camchain") camchain = next();
      else if (a == "--mount") mount = next();
      else if (a == "--image") image_path = next();
      else if (a == "--targets") targets = next();
      else if (a == "--repeats") repeats = static_cast<int>(cli::parseInt(a, next(), 1, 10000));
      else return false;
      return true;
    });
    if (config.empty()) throw cli::UsageError("--config is required");
    cli::requireInputFile("--config", config);
    if (!image_path.empty()) {
      cli::requireInputFile("--image", image_path);
    } else {
      if (camchain.empty() || mount.empty()) throw cli::UsageError("--camchain and --mount (or --image) are required");
      cli::requireInputFile("--camchain", camchain);
      cli::requireInputFile("--mount", mount);
    }
    std::stringstream ts(targets);
    int n_targets = 0;
    for (std::string t; std::getline(ts, t, ',');) {
      if (t.empty()) throw cli::UsageError("--targets: empty name in '" + targets + "'");
      if (++n_targets > 16) throw cli::UsageError("--targets: at most 16 targets");
    }
    if (n_targets == 0) throw cli::UsageError("--targets needs at least one target");
  });
  if (rc >= 0) return rc;
  try {
    if (config.empty()) throw std::runtime_error("--config is required");
    const fm::DetectorModelConfig cfg = fm::loadDetectorConfig(config);
    cv::Mat image;
    std::string source;
    if (!image_path.empty()) {
      image = cv::imread(image_path, cv::IMREAD_GRAYSCALE);
      if (image.empty()) throw std::runtime_error("cannot read " + image_path);
      source = image_path;
    } else {
      if (camchain.empty() || mount.empty()) throw std::runtime_error("--camchain and --mount (or --image) are required");
      const fm::Rig rig = fm::loadKalibrRig(camchain, mount);
      fm::synth::WorldConfig wc;
      wc.seed = 7;
      const fm::synth::World world(wc);
      const auto& cam = rig.cameras[0];
      const double t = 6.0;
      image = world.render(cam.model, fm::pixelRays(cam.model), world.egoPose(t) * cam.T_base_cam, t, 1).image;
      source = "rendered urban frame of " + cam.name;
    }
    std::printf("detector benchmark: %s head, input %dx%d, image %dx%d (%s), %d repeats, OpenCV %s\n",
                fm::headName(cfg.head), cfg.input_width, cfg.input_height, image.cols, image.rows, source.c_str(),
                repeats, CV_VERSION);
    std::printf("| target | device used | median ms | min ms | detections |\n|---|---|---|---|---|\n");
    std::stringstream ss(targets);
    for (std::string target; std::getline(ss, target, ',');) {
      fm::DnnDevice dev;
      dev.target = target;
      fm::Detector det(cfg, dev);
      std::vector<fm::Detection> dets = det.detect(image);  // warm-up (kernel builds, allocation)
      det.detect(image);
      std::string used = "CPU";
      if (target != "cpu") {
        // OpenCV's DNN runs its OpenCL target on GPUs only and otherwise falls back to the
        // CPU, unless OPENCV_DNN_OPENCL_ALLOW_ALL_DEVICES=1.
        const char* all = std::getenv("OPENCV_DNN_OPENCL_ALLOW_ALL_DEVICES");
        const bool any = all && std::string(all) == "1";
        if (!cv::ocl::haveOpenCL()) {
          used = "CPU (no OpenCL runtime in OpenCV: fell back)";
        } else {
          cv::ocl::Context::getDefault(true);
          const cv::ocl::Device& d = cv::ocl::Device::getDefault();
          const bool gpu = d.type() == cv::ocl::Device::TYPE_GPU;
          used = d.name().empty() ? std::string("no OpenCL GPU: OpenCV fell back to CPU")
                                  : "OpenCL device '" + d.name() + "'" + (gpu || any ? "" : " (not a GPU: CPU fallback)");
        }
      }
      std::vector<double> ms;
      for (int r = 0; r < repeats; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        dets = det.detect(image);
        ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      }
      std::sort(ms.begin(), ms.end());
      std::string names;
      for (const auto& d : dets) names += (names.empty() ? "" : ", ") + d.class_name;
      std::printf("| %s | %s | %.1f | %.1f | %zu (%s) |\n", target.c_str(), used.c_str(), ms[ms.size() / 2], ms[0],
                  dets.size(), names.c_str());
    }
  } catch (const std::exception& e) {
    std::cerr << "detector_benchmark: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
