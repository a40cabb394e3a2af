// C++ face of the camera models: a value type over the shared parameter struct.
//
// The maths lives in camera_model_shared.h (one copy for C++ and OpenCL); this
// class adds construction with checked parameters, the derived domain limits,
// Eigen types and a double-precision API. Thread-safe: all methods are const
// after construction.
#ifndef FISHEYE_MAPPING_CORE_CAMERA_CAMERA_MODEL_H_
#define FISHEYE_MAPPING_CORE_CAMERA_CAMERA_MODEL_H_

#include <string>
#include <vector>

#include <Eigen/Core>

#include "fisheye_mapping/core/camera/camera_model_shared.h"

namespace fisheye_mapping {

enum class CameraModelType {
  kPinhole = FM_MODEL_PINHOLE,             // pinhole + radtan (k1 k2 p1 p2)
  kUnified = FM_MODEL_UNIFIED,             // Mei unified + radtan (Kalibr "omni")
  kDoubleSphere = FM_MODEL_DOUBLE_SPHERE,  // Kalibr "ds"
  kKannalaBrandt = FM_MODEL_KANNALA_BRANDT,  // Kalibr "pinhole" + "equidistant"
};

// Limits of a plausible camera; the factories reject anything beyond them (a
// broken calibration file, not a lens), so no loop over pixels or angles can
// run away and no field of view comes out as 0 deg.
constexpr int kMaxImageSide = 20000;            // pixels, width and height
constexpr double kMaxFocalLength = 1e6;         // pixels: fx, fy in (0, 1e6]; |skew| too
constexpr double kMaxPrincipalPoint = 1e6;      // pixels: |cx|, |cy|
constexpr double kMaxFocalRatio = 10;           // fx/fy and fy/fx at most; cx, cy inside the image
constexpr double kMaxDistortionCoeff = 1e3;     // |k1..k4|, |p1|, |p2|
constexpr double kMaxUnifiedXi = 1e3;           // unified xi in [0, 1e3]
// project() returns false for points farther than this along any axis
// (metres), as for non-finite points.
constexpr double kMaxProjectDistance = 1e30;

// Intrinsics common to every model. Distortion coefficients a model does not
// use must be zero.
struct Intrinsics {
  int width = 0;
  int height = 0;
  double fx = 0.0;
  double fy = 0.0;
  double cx = 0.0;
  double cy = 0.0;
  double skew = 0.0;
};

class CameraModel {
 public:
  // Each factory checks its parameters and throws std::invalid_argument whose
  // message names the offending parameter (e.g. "fx must be positive, got -3").
  static CameraModel pinhole(const Intrinsics& in, double k1 = 0, double k2 = 0, double p1 = 0,
                             double p2 = 0);
  static CameraModel unified(const Intrinsics& in, double xi, double k1 = 0, double k2 = 0,
                             double p1 = 0, double p2 = 0);
  static CameraModel doubleSphere(const Intrinsics& in, double xi, double alpha);
  static CameraModel kannalaBrandt(const Intrinsics& in, double k1 = 0, double k2 = 0,
                                   double k3 = 0, double k4 = 0);

  CameraModel() = default;

  CameraModelType type() const { return static_cast<CameraModelType>(params_.model); }
  // "pinhole-radtan", "omni-radtan", "ds-none", "pinhole-equidistant".
  std::string name() const;
  int width() const { return params_.width; }
  int height() const { return params_.height; }

  // Point in the camera frame -> pixel. False (and *uv unspecified) outside the
  // model's valid domain, for a non-finite point, the origin, or a coordinate
  // beyond kMaxProjectDistance; the image bounds are not checked (see isInImage).
  bool project(const Eigen::Vector3d& p_C, Eigen::Vector2d* uv) const;
  // Pixel -> unit ray in the camera frame. False outside the valid domain or
  // for a non-finite pixel.
  bool unproject(const Eigen::Vector2d& uv, Eigen::Vector3d* ray_C) const;
  // Pixel inside [margin, width-1-margin] x [margin, height-1-margin].
  bool isInImage(const Eigen::Vector2d& uv, double margin = 0.0) const;

  // Largest angle between the optical axis and a ray of the valid domain
  // (radians); may exceed pi/2.
  double maxValidAngle() const;

  // The same camera for an image resampled by `scale` (0.5: half resolution,
  // pixel centres kept consistent: c' = (c + 0.5) * scale - 0.5) to
  // width x height pixels.
  CameraModel scaled(double scale, int width, int height) const;
  // The same camera for the crop of width x height pixels at (x0, y0).
  CameraModel cropped(int x0, int y0, int width, int height) const;

  const FmCameraT<double>& params() const { return params_; }
  // The same parameters in single precision, laid out as the OpenCL struct.
  FmCameraT<float> floatParams() const;

 private:
  static CameraModel make(CameraModelType type, const Intrinsics& in);
  FmCameraT<double> params_{};
};

// Unit ray of every pixel centre (row-major, width * height), NaN where the
// pixel is outside the model's domain. Unprojection inverts distortion by
// Newton steps: compute this once per camera, not per frame. Uses all cores.
std::vector<Eigen::Vector3f> pixelRays(const CameraModel& camera);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_CAMERA_CAMERA_MODEL_H_
