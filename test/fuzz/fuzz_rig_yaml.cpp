// libFuzzer target: the Kalibr camchain + mount YAML loader
// (loadKalibrRigFromStrings). The input is the camchain text, optionally
// followed by a line "%%MOUNT%%" and the mount text (else a fixed good mount).
// Allowed outcomes: a rig whose every number is finite and whose frame ids are
// unique, or a CalibrationError; anything else (another exception, a crash, a
// sanitizer report) is a finding.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <set>
#include <string>

#include "fisheye_mapping/core/camera/rig.h"

namespace fm = fisheye_mapping;

namespace {

const char* kMount =
    "base_frame: base_link\n"
    "T_base_cam0:\n"
    "  - [0.0, 0.0, 1.0, 1.5]\n"
    "  - [-1.0, 0.0, 0.0, 0.0]\n"
    "  - [0.0, -1.0, 0.0, 1.6]\n"
    "  - [0.0, 0.0, 0.0, 1.0]\n";

[[noreturn]] void finding(const std::string& what) {
  std::fprintf(stderr, "fuzz_rig_yaml: %s\n", what.c_str());
  std::abort();
}

void checkRig(const fm::Rig& rig) {
  if (rig.cameras.empty() || static_cast<int>(rig.cameras.size()) > fm::kMaxRigCameras) finding("camera count");
  std::set<std::string> frames;
  for (const auto& cam : rig.cameras) {
    if (!cam.T_base_cam.matrix().allFinite() || !cam.T_cam0_cam.matrix().allFinite()) finding("non-finite pose");
    if (cam.frame_id.empty() || cam.frame_id == rig.base_frame || !frames.insert(cam.frame_id).second)
      finding("frame id '" + cam.frame_id + "' empty, the base frame or shared");
    const auto& p = cam.model.params();
    if (p.width < 1 || p.height < 1 || p.width > fm::kMaxImageSide || p.height > fm::kMaxImageSide) finding("size");
    if (!(p.fx > 0 && p.fx <= fm::kMaxFocalLength && p.fy > 0 && p.fy <= fm::kMaxFocalLength)) finding("focal");
    // The model must answer without crashing; the principal point's ray is the axis.
    Eigen::Vector3d ray;
    Eigen::Vector2d uv;
    if (cam.model.unproject(Eigen::Vector2d(p.cx, p.cy), &ray) && !ray.allFinite()) finding("ray");
    if (cam.model.project(Eigen::Vector3d(0.1, -0.2, 1.0), &uv) && !uv.allFinite()) finding("pixel");
    cam.model.project(Eigen::Vector3d(1e155, 1e155, 1e155), &uv);
  }
}

}  // namespace

// The normal suite (test/test_fuzz_regressions.cpp) links this file with the
// entry point renamed by FM_FUZZ_ENTRY and replays test/fuzz/<target>/.
#ifndef FM_FUZZ_ENTRY
#define FM_FUZZ_ENTRY LLVMFuzzerTestOneInput
#endif
extern "C" int FM_FUZZ_ENTRY(const uint8_t* data, size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  std::string chain = input, mount = kMount;
  const size_t sep = input.find("%%MOUNT%%");
  if (sep != std::string::npos) {
    chain = input.substr(0, sep);
    mount = input.substr(sep + 9);
  }
  try {
    checkRig(fm::loadKalibrRigFromStrings(chain, mount, "camchain.yaml", "mount.yaml"));
  } catch (const fm::CalibrationError& e) {
    const std::string msg = e.what();
    if (msg.find("camchain.yaml") == std::string::npos && msg.find("mount.yaml") == std::string::npos)
      finding("error without the file name: " + msg);
  }
  return 0;
}
