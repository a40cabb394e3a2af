// rig_info: inspect a camera rig.
//
//   rig_info --camchain camchain.yaml --mount mount.yaml          summary
//   rig_info --psl calib.txt --size 1280x800                      PlaneSweepLib calib
//   ... --project CAM    reads "x y z" lines (metres, CAM frame), prints "u v" or "invalid"
//   ... --unproject CAM  reads "u v" lines, prints the unit ray "x y z" or "invalid"
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "fisheye_mapping/core/rig.h"
#include "fisheye_mapping/core/rig_geometry.h"

namespace fm = fisheye_mapping;

namespace {

const char* kUsage =
    "usage: rig_info (--camchain FILE --mount FILE | --psl FILE --size WxH)\n"
    "                [--range METRES] [--project CAM | --unproject CAM]\n"
    "  Without --project/--unproject: prints each camera's model, resolution,\n"
    "  field of view, position relative to cam0 and the base frame, and the\n"
    "  overlap of each pair's fields of view at --range metres (default 20).\n"
    "  --project CAM   reads lines 'x y z' (metres, CAM's optical frame) on stdin\n"
    "                  and prints 'u v' (pixels) or 'invalid' per line.\n"
    "  --unproject CAM reads lines 'u v' and prints the unit ray 'x y z' or 'invalid'.\n"
    "  'invalid' means outside the model's valid domain (or, for --project,\n"
    "  outside the image). Exit status 1 if an input line could not be parsed.\n";

// Parses exactly n finite numbers from a line.
bool parseNumbers(const std::string& line, int n, std::vector<double>* out) {
  std::istringstream ss(line);
  out->clear();
  double v;
  while (ss >> v) out->push_back(v);
  if (!ss.eof()) return false;
  if (static_cast<int>(out->size()) != n) return false;
  for (double x : *out) {
    if (!std::isfinite(x)) return false;
  }
  return true;
}

// Prints -0 as 0.
double clean(double x) { return std::abs(x) < 5e-13 ? 0.0 : x; }

int runFilter(const fm::RigCamera& cam, bool project) {
  std::string line;
  std::vector<double> in;
  int line_no = 0;
  int status = 0;
  while (std::getline(std::cin, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    if (!parseNumbers(line, project ? 3 : 2, &in)) {
      std::cerr << "rig_info: line " << line_no << ": expected " << (project ? "'x y z'" : "'u v'")
                << ", got '" << line << "'\n";
      std::printf("invalid\n");
      status = 1;
      continue;
    }
    if (project) {
      Eigen::Vector2d uv;
      if (cam.model.project(Eigen::Vector3d(in[0], in[1], in[2]), &uv) && cam.model.isInImage(uv)) {
        std::printf("%.9f %.9f\n", uv.x(), uv.y());
      } else {
        std::printf("invalid\n");
      }
    } else {
      Eigen::Vector3d ray;
      if (cam.model.unproject(Eigen::Vector2d(in[0], in[1]), &ray)) {
        std::printf("%.12f %.12f %.12f\n", clean(ray.x()), clean(ray.y()), clean(ray.z()));
      } else {
        std::printf("invalid\n");
      }
    }
  }
  return status;
}

void printSummary(const fm::Rig& rig, double range) {
  std::printf("rig: %zu camera(s), base frame '%s'\n", rig.cameras.size(), rig.base_frame.c_str());
  for (const auto& cam : rig.cameras) {
    const auto& p = cam.model.params();
    const fm::FieldOfView fov = fm::computeFieldOfView(cam.model);
    std::printf("\n%s: %s %dx%d  frame '%s'  topic '%s'\n", cam.name.c_str(),
                cam.model.name().c_str(), p.width, p.height, cam.frame_id.c_str(),
                cam.rostopic.c_str());
    std::printf("  intrinsics: fx %.3f fy %.3f cx %.3f cy %.3f", p.fx, p.fy, p.cx, p.cy);
    if (cam.model.type() == fm::CameraModelType::kUnified) std::printf(" xi %.4f", p.xi);
    if (cam.model.type() == fm::CameraModelType::kDoubleSphere) {
      std::printf(" xi %.4f alpha %.4f", p.xi, p.alpha);
    }
    std::printf("\n  field of view: horizontal %.1f deg, vertical %.1f deg, max off-axis %.1f deg\n",
                fov.horizontal_deg, fov.vertical_deg, fov.max_off_axis_deg);
    const Eigen::Vector3d t0 = cam.T_cam0_cam.translation();
    const Eigen::Vector3d tb = cam.T_base_cam.translation();
    std::printf("  position in cam0 [m]: %8.4f %8.4f %8.4f  (baseline %.4f)\n", clean(t0.x()),
                clean(t0.y()), clean(t0.z()), t0.norm());
    std::printf("  position in %s [m]: %8.4f %8.4f %8.4f\n", rig.base_frame.c_str(), clean(tb.x()),
                clean(tb.y()), clean(tb.z()));
    const Eigen::Vector3d axis = cam.T_base_cam.linear().col(2);
    std::printf("  optical axis in %s: yaw %.1f deg, pitch %.1f deg (positive = up)\n",
                rig.base_frame.c_str(), clean(std::atan2(clean(axis.y()), axis.x()) * 180.0 / M_PI),
                clean(std::asin(std::clamp(clean(axis.z()), -1.0, 1.0)) * 180.0 / M_PI));
  }
  if (rig.cameras.size() < 2) return;
  std::printf("\noverlap at %.1f m: share of the row camera's pixels seen by the column camera\n",
              range);
  std::printf("%8s", "");
  for (const auto& b : rig.cameras) std::printf(" %7s", b.name.c_str());
  std::printf("\n");
  for (const auto& a : rig.cameras) {
    std::printf("%8s", a.name.c_str());
    for (const auto& b : rig.cameras) std::printf(" %7.3f", fm::computeOverlap(a, b, range));
    std::printf("\n");
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string camchain, mount, psl, size, project_cam, unproject_cam;
  double range = 20.0;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&](std::string* out) {
      if (i + 1 >= argc) {
        std::cerr << "rig_info: " << arg << " needs a value\n" << kUsage;
        std::exit(2);
      }
      *out = argv[++i];
    };
    std::string range_text;
    if (arg == "--camchain") value(&camchain);
    else if (arg == "--mount") value(&mount);
    else if (arg == "--psl") value(&psl);
    else if (arg == "--size") value(&size);
    else if (arg == "--project") value(&project_cam);
    else if (arg == "--unproject") value(&unproject_cam);
    else if (arg == "--range") {
      value(&range_text);
      char* end = nullptr;
      range = std::strtod(range_text.c_str(), &end);
      if (*end != '\0' || !(range > 0.0) || !std::isfinite(range)) {
        std::cerr << "rig_info: --range must be a positive number of metres, got '" << range_text << "'\n";
        return 2;
      }
    } else if (arg == "-h" || arg == "--help") {
      std::cout << kUsage;
      return 0;
    } else {
      std::cerr << "rig_info: unknown argument '" << arg << "'\n" << kUsage;
      return 2;
    }
  }
  if (!project_cam.empty() && !unproject_cam.empty()) {
    std::cerr << "rig_info: give --project or --unproject, not both\n";
    return 2;
  }
  try {
    fm::Rig rig;
    if (!psl.empty()) {
      int w = 0, h = 0;
      char x = 0;
      std::istringstream ss(size);
      if (!(ss >> w >> x >> h) || x != 'x' || w <= 0 || h <= 0) {
        std::cerr << "rig_info: --psl needs --size WxH (e.g. 1280x800), got '" << size << "'\n";
        return 2;
      }
      rig = fm::loadPslCalibration(psl, w, h);
    } else if (!camchain.empty() && !mount.empty()) {
      rig = fm::loadKalibrRig(camchain, mount);
    } else {
      std::cerr << "rig_info: give --camchain and --mount, or --psl and --size\n" << kUsage;
      return 2;
    }
    if (!project_cam.empty()) return runFilter(rig.camera(project_cam), true);
    if (!unproject_cam.empty()) return runFilter(rig.camera(unproject_cam), false);
    printSummary(rig, range);
  } catch (const fm::CalibrationError& e) {
    std::cerr << "rig_info: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
