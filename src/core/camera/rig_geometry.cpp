#include "fisheye_mapping/core/camera/rig_geometry.h"

#include <algorithm>
#include <cmath>

namespace fisheye_mapping {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

// Signed angles (in the plane of the axis and `axis_component`) of the first
// and last valid rays along a line of pixels; returns their difference.
template <typename PixelAt, typename AngleOf>
double spanAlong(const CameraModel& model, int count, PixelAt pixel_at, AngleOf angle_of) {
  double lo = 0.0, hi = 0.0;
  bool any = false;
  for (int i = 0; i < count; ++i) {
    Eigen::Vector3d ray;
    if (!model.unproject(pixel_at(i), &ray)) continue;
    const double a = angle_of(ray);
    lo = any ? std::min(lo, a) : a;
    hi = any ? std::max(hi, a) : a;
    any = true;
  }
  return any ? (hi - lo) * kRadToDeg : 0.0;
}

}  // namespace

FieldOfView computeFieldOfView(const CameraModel& model) {
  const auto& p = model.params();
  // The row and column through the principal point, kept inside the image.
  const double row = std::clamp(p.cy, 0.0, double(model.height() - 1));
  const double col = std::clamp(p.cx, 0.0, double(model.width() - 1));
  FieldOfView fov;
  fov.horizontal_deg = spanAlong(
      model, model.width(), [&](int i) { return Eigen::Vector2d(i, row); },
      [](const Eigen::Vector3d& r) { return std::atan2(r.x(), r.z()); });
  fov.vertical_deg = spanAlong(
      model, model.height(), [&](int i) { return Eigen::Vector2d(col, i); },
      [](const Eigen::Vector3d& r) { return std::atan2(r.y(), r.z()); });
  double max_angle = 0.0;
  const int step = 2;
  for (int v = 0; v < model.height(); v += step) {
    for (int u = 0; u < model.width(); u += step) {
      Eigen::Vector3d ray;
      if (model.unproject(Eigen::Vector2d(u, v), &ray)) {
        max_angle = std::max(max_angle, std::acos(std::clamp(ray.z(), -1.0, 1.0)));
      }
    }
  }
  fov.max_off_axis_deg = max_angle * kRadToDeg;
  return fov;
}

double computeOverlap(const RigCamera& a, const RigCamera& b, double range_m, int step) {
  const Eigen::Isometry3d T_b_a = b.T_cam0_cam.inverse() * a.T_cam0_cam;
  int total = 0, seen = 0;
  // Cell centres, so no sample sits exactly on the image border.
  for (int v = step / 2; v < a.model.height(); v += step) {
    for (int u = step / 2; u < a.model.width(); u += step) {
      Eigen::Vector3d ray;
      if (!a.model.unproject(Eigen::Vector2d(u, v), &ray)) continue;
      ++total;
      Eigen::Vector2d uv;
      if (b.model.project(T_b_a * (range_m * ray), &uv) && b.model.isInImage(uv)) ++seen;
    }
  }
  return total > 0 ? static_cast<double>(seen) / total : 0.0;
}

}  // namespace fisheye_mapping
