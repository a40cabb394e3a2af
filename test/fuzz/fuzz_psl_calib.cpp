// libFuzzer target: PlaneSweepLib's calib.txt parser
// (loadPslCalibrationFromString) at 1280x800. Allowed outcomes: a rig with one
// finite camera, or a CalibrationError naming the file.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "fisheye_mapping/core/camera/rig.h"

namespace fm = fisheye_mapping;

// The normal suite (test/test_fuzz_regressions.cpp) links this file with the
// entry point renamed by FM_FUZZ_ENTRY and replays test/fuzz/<target>/.
#ifndef FM_FUZZ_ENTRY
#define FM_FUZZ_ENTRY LLVMFuzzerTestOneInput
#endif
extern "C" int FM_FUZZ_ENTRY(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const fm::Rig rig = fm::loadPslCalibrationFromString(text, "calib.txt", 1280, 800);
    if (rig.cameras.size() != 1 || !rig.cameras[0].T_base_cam.matrix().allFinite()) {
      std::fprintf(stderr, "fuzz_psl_calib: bad rig\n");
      std::abort();
    }
    Eigen::Vector3d ray;
    rig.cameras[0].model.unproject(Eigen::Vector2d(640, 400), &ray);
  } catch (const fm::CalibrationError& e) {
    if (std::string(e.what()).find("calib.txt") == std::string::npos) {
      std::fprintf(stderr, "fuzz_psl_calib: error without the file name: %s\n", e.what());
      std::abort();
    }
  }
  return 0;
}
