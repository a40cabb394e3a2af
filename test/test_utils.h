// Shared fixtures for the core tests: the camera models exercised everywhere.
#ifndef FISHEYE_MAPPING_TEST_TEST_UTILS_H_
#define FISHEYE_MAPPING_TEST_TEST_UTILS_H_

#include <cstdlib>
#include <string>
#include <utility>
#include <vector>

#include "fisheye_mapping/core/camera/camera_model.h"

namespace fisheye_mapping {
namespace test {

inline Intrinsics makeIntrinsics(double fx, double fy, double cx, double cy, int w = 1024,
                                 int h = 544) {
  Intrinsics in;
  in.width = w;
  in.height = h;
  in.fx = fx;
  in.fy = fy;
  in.cx = cx;
  in.cy = cy;
  return in;
}

// One realistic camera of each model and regime (xi below and above 1).
inline std::vector<std::pair<std::string, CameraModel>> realisticCameras() {
  return {
      {"pinhole_radtan", CameraModel::pinhole(makeIntrinsics(400, 410, 320, 240, 640, 480), -0.28,
                                              0.07, 1e-3, -5e-4)},
      {"unified_xi_0.98",
       CameraModel::unified(makeIntrinsics(520, 520, 511.5, 271.5), 0.98, -0.02, 0.004, 2e-4, -1e-4)},
      // The V-Charge calibration of ../shared (xi > 1).
      {"unified_vcharge_xi_1.158",
       CameraModel::unified(makeIntrinsics(895.548, 894.744, 649.624, 398.719, 1280, 800), 1.15844,
                            -0.330843, 0.0865198, -6.76787e-4, -3.64130e-5)},
      {"unified_xi_2.8", CameraModel::unified(makeIntrinsics(2000, 2000, 640, 400, 1280, 800), 2.8,
                                              -0.1, 0.02, 0.0, 0.0)},
      {"double_sphere", CameraModel::doubleSphere(makeIntrinsics(350, 350, 511.5, 271.5), -0.18, 0.59)},
      {"kannala_brandt", CameraModel::kannalaBrandt(makeIntrinsics(330, 330, 511.5, 271.5), 0.02,
                                                    -0.005, 0.001, -0.0002)},
  };
}

// ../shared beside the repository (FISHEYE_MAPPING_SHARED_DIR overrides).
inline std::string sharedDir(const char* compiled_default) {
  const char* env = std::getenv("FISHEYE_MAPPING_SHARED_DIR");
  return env ? env : compiled_default;
}

}  // namespace test
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_TEST_TEST_UTILS_H_
