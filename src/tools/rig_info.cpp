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
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "cli.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/camera/rig_geometry.h"

namespace fm = fisheye_mapping;

namespace {

const char* kUsage =
    "usage: rig_info (--camchain FILE --mount FILE | --psl FILE --size WxH)\n"
    "                [--range METRES] [--project CAM | --unproject CAM]\n"
    "  --camchain FILE, --mount FILE  the rig (Kalibr camchain and mount)\n"
    "  --psl FILE, --size WxH         or a PlaneSweepLib calibration and its image size\n"
    "  Without --project/--unproject: prints each camera's model, resolution,\n"
    "  field of view, position relative to cam0 and the base frame, and the\n"
    "  overlap of each pair's fields of view at --range metres (default 20).\n"
    "  --project CAM   reads lines 'x y z' (metres, CAM's optical frame) on stdin\n"
    "                  and prints 'u v' (pixels) or 'invalid' per line.\n"
    "  --unproject CAM reads lines 'u v' and prints the unit ray 'x y z' or 'invalid'.\n"
    "  'invalid' means outside the model's valid domain (or, for --project,\n"
    "  outside the image). Exit status 1 if an input line could not be parsed\n"
    "  (or is longer than 4096 characters), 2 on bad options or calibration.\n";

// Prints -0 as 0.
double clean(double x) { return std::abs(x) < 5e-13 ? 0.0 : x; }

}  // namespace

// The --project / --unproject line filter, callable on its own (the fuzz
// target test/fuzz/rig_info_lines calls it).
namespace rig_info {

// Longest input line read; the rest of a longer line is skipped.
constexpr size_t kMaxLineLength = 4096;

// Exactly n finite numbers separated by blanks (space, tab, CR), nothing else.
bool parseNumbers(const std::string& line, int n, std::vector<double>* out) {
  out->clear();
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    if (i == line.size()) break;
    size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '\r') ++j;
    if (static_cast<int>(out->size()) == n) return false;  // too many
    const std::string tok = line.substr(i, j - i);
    double v = 0;
    if (!fm::cli::parseDecimal(tok, &v)) return false;  // decimal only: no 0x10, nan, inf
    out->push_back(v);
    i = j;
  }
  return static_cast<int>(out->size()) == n;
}

// One input line -> one output line (without newline): "u v", the ray
// "x y z", or "invalid". *parsed is false when the line is not n numbers.
std::string filterLine(const fm::CameraModel& model, bool project, const std::string& line, bool* parsed) {
  std::vector<double> in;
  *parsed = parseNumbers(line, project ? 3 : 2, &in);
  if (!*parsed) return "invalid";
  char buf[160];
  if (project) {
    Eigen::Vector2d uv;
    if (!model.project(Eigen::Vector3d(in[0], in[1], in[2]), &uv) || !model.isInImage(uv)) return "invalid";
    std::snprintf(buf, sizeof(buf), "%.9f %.9f", uv.x(), uv.y());
  } else {
    Eigen::Vector3d ray;
    if (!model.unproject(Eigen::Vector2d(in[0], in[1]), &ray)) return "invalid";
    std::snprintf(buf, sizeof(buf), "%.12f %.12f %.12f", clean(ray.x()), clean(ray.y()), clean(ray.z()));
  }
  return buf;
}

// Reads one line of at most kMaxLineLength characters (the rest of a longer
// line is read and dropped, *too_long set). False at the end of input.
bool readLine(std::istream& in, std::string* line, bool* too_long) {
  line->clear();
  *too_long = false;
  int c = 0;
  bool any = false;
  while ((c = in.get()) != EOF) {
    any = true;
    if (c == '\n') return true;
    if (line->size() < kMaxLineLength) line->push_back(static_cast<char>(c));
    else *too_long = true;
  }
  return any;
}

}  // namespace rig_info

#ifndef FM_RIG_INFO_NO_MAIN  // the fuzz target and the regression test take the filter above alone
namespace {

int runFilter(const fm::RigCamera& cam, bool project) {
  std::string line;
  int line_no = 0;
  int status = 0;
  bool too_long = false;
  while (rig_info::readLine(std::cin, &line, &too_long)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos && !too_long) continue;
    bool parsed = false;
    const std::string out = too_long ? "invalid" : rig_info::filterLine(cam.model, project, line, &parsed);
    if (too_long) {
      std::cerr << "rig_info: line " << line_no << ": longer than " << rig_info::kMaxLineLength
                << " characters\n";
      status = 1;
    } else if (!parsed) {
      std::cerr << "rig_info: line " << line_no << ": expected " << (project ? "'x y z'" : "'u v'")
                << " (finite numbers), got '" << line.substr(0, 200) << (line.size() > 200 ? "...'" : "'") << "\n";
      status = 1;
    }
    std::printf("%s\n", out.c_str());
  }
  return status;
}

// The cameras' fields of view and overlaps are scanned pixel by pixel; a large
// camera is scanned at a reduced resolution (the same angles, sampled more
// coarsely), so the summary takes bounded time whatever the resolution.
constexpr int kMaxScanSide = 2048;     // field of view
constexpr int kMaxOverlapSide = 1024;  // overlap, per pair of cameras

fm::CameraModel scanModel(const fm::CameraModel& model, int max_side) {
  const int side = std::max(model.width(), model.height());
  if (side <= max_side) return model;
  const double s = static_cast<double>(max_side) / side;
  return model.scaled(s, std::max(1, static_cast<int>(std::lround(model.width() * s))),
                      std::max(1, static_cast<int>(std::lround(model.height() * s))));
}

void printSummary(const fm::Rig& rig, double range) {
  std::printf("rig: %zu camera(s), base frame '%s'\n", rig.cameras.size(), rig.base_frame.c_str());
  for (const auto& cam : rig.cameras) {
    const auto& p = cam.model.params();
    const fm::CameraModel scan = scanModel(cam.model, kMaxScanSide);
    const fm::FieldOfView fov = fm::computeFieldOfView(scan);
    std::printf("\n%s: %s %dx%d  frame '%s'  topic '%s'\n", cam.name.c_str(),
                cam.model.name().c_str(), p.width, p.height, cam.frame_id.c_str(),
                cam.rostopic.c_str());
    std::printf("  intrinsics: fx %.3f fy %.3f cx %.3f cy %.3f", p.fx, p.fy, p.cx, p.cy);
    if (cam.model.type() == fm::CameraModelType::kUnified) std::printf(" xi %.4f", p.xi);
    if (cam.model.type() == fm::CameraModelType::kDoubleSphere) {
      std::printf(" xi %.4f alpha %.4f", p.xi, p.alpha);
    }
    std::printf("\n  field of view: horizontal %.1f deg, vertical %.1f deg, max off-axis %.1f deg",
                fov.horizontal_deg, fov.vertical_deg, fov.max_off_axis_deg);
    if (scan.width() != p.width || scan.height() != p.height) {
      std::printf(" (sampled at %dx%d)", scan.width(), scan.height());
    }
    std::printf("\n");
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
  for (const auto& cam : rig.cameras) {
    fm::RigCamera a = cam;
    a.model = scanModel(cam.model, kMaxOverlapSide);
    std::printf("%8s", a.name.c_str());
    for (const auto& b : rig.cameras) std::printf(" %7.3f", fm::computeOverlap(a, b, range));
    std::printf("\n");
  }
}

}  // namespace

int main(int argc, char** argv) {
  namespace cli = fm::cli;
  std::string camchain, mount, psl, size;
  std::optional<std::string> project_cam, unproject_cam;  // set, even to '', means the filter
  double range = 20.0;
  const int rc = cli::parseCommandLine("rig_info", kUsage, [&] {
    cli::forEachOption(argc, argv, 1, [&](const std::string& arg, const cli::NextValue& value) {
      if (arg == "--camchain") camchain = value();
      else if (arg == "--mount") mount = value();
      else if (arg == "--psl") psl = value();
      else if (arg == "--size") size = value();
      else if (arg == "--project") project_cam = value();
      else if (arg == "--unproject") unproject_cam = value();
      else if (arg == "--range") range = cli::parsePositive(arg, value(), 1e6);
      else return false;
      return true;
    });
    if (project_cam && unproject_cam) throw cli::UsageError("give --project or --unproject, not both");
    for (const auto& [opt, cam] : {std::pair{"--project", project_cam}, std::pair{"--unproject", unproject_cam}})
      if (cam && cam->empty()) throw cli::UsageError(std::string(opt) + " needs a camera name, got ''");
    if (!psl.empty() && (!camchain.empty() || !mount.empty())) {
      throw cli::UsageError("give --camchain and --mount, or --psl and --size, not both");
    }
    if (psl.empty() && (camchain.empty() || mount.empty())) {
      throw cli::UsageError("give --camchain and --mount, or --psl and --size");
    }
  });
  if (rc >= 0) return rc;
  try {
    fm::Rig rig;
    if (!psl.empty()) {
      int w = 0, h = 0;
      if (size.empty()) throw cli::UsageError("--psl needs --size WxH (e.g. 1280x800)");
      cli::parseSize("--size", size, fm::kMaxImageSide, &w, &h);
      cli::requireInputFile("--psl", psl);
      rig = fm::loadPslCalibration(psl, w, h);
    } else {
      cli::requireInputFile("--camchain", camchain);
      cli::requireInputFile("--mount", mount);
      rig = fm::loadKalibrRig(camchain, mount);
    }
    if (project_cam) return runFilter(rig.camera(*project_cam), true);
    if (unproject_cam) return runFilter(rig.camera(*unproject_cam), false);
    printSummary(rig, range);
  } catch (const cli::UsageError& e) {
    std::cerr << "rig_info: " << e.what() << "\n";
    return 2;
  } catch (const fm::CalibrationError& e) {
    std::cerr << "rig_info: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "rig_info: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
#endif  // FM_RIG_INFO_NO_MAIN
