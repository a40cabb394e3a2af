// Analytic scenes (ground plane, spheres, boxes): exact signed distance, and
// ray casting to depth images of any camera model (range along the ray, NaN
// where no surface). Ground truth for the TSDF tests and the benchmark frames.
#ifndef FISHEYE_MAPPING_CORE_SIM_ANALYTIC_SCENE_H_
#define FISHEYE_MAPPING_CORE_SIM_ANALYTIC_SCENE_H_

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/camera_model.h"

namespace fisheye_mapping {
namespace analytic {

struct Sphere {
  Eigen::Vector3d c;
  double r;
};
struct Box {
  Eigen::Vector3d lo, hi;
};

struct Scene {
  bool ground = true;           // plane z = 0, solid below
  double ground_extent = 1e9;   // |x|, |y| limit of the ground's visible part
  std::vector<Sphere> spheres;
  std::vector<Box> boxes;
  double min_incidence_cos = 0.5;  // grazing rays give no depth (as stereo would)

  // Signed distance to the union of the shapes (negative inside).
  double sdf(const Eigen::Vector3d& p) const {
    double d = ground ? p.z() : std::numeric_limits<double>::infinity();
    for (const auto& s : spheres) d = std::min(d, (p - s.c).norm() - s.r);
    for (const auto& b : boxes) {
      const Eigen::Vector3d c = 0.5 * (b.lo + b.hi), h = 0.5 * (b.hi - b.lo);
      const Eigen::Vector3d q = (p - c).cwiseAbs() - h;
      d = std::min(d, q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0));
    }
    return d;
  }

  // Distance along the unit ray d from o to the first surface, with the
  // surface normal; infinity if none.
  double cast(const Eigen::Vector3d& o, const Eigen::Vector3d& d, Eigen::Vector3d* n) const {
    double best = std::numeric_limits<double>::infinity();
    if (ground && d.z() < 0 && o.z() > 0) {
      const double t = -o.z() / d.z();
      const Eigen::Vector3d p = o + t * d;
      if (std::abs(p.x()) < ground_extent && std::abs(p.y()) < ground_extent && t < best) {
        best = t;
        *n = Eigen::Vector3d::UnitZ();
      }
    }
    for (const auto& s : spheres) {
      const Eigen::Vector3d oc = o - s.c;
      const double b = oc.dot(d), c = oc.squaredNorm() - s.r * s.r, disc = b * b - c;
      if (disc < 0) continue;
      const double t = -b - std::sqrt(disc);
      if (t > 0 && t < best) {
        best = t;
        *n = (o + t * d - s.c).normalized();
      }
    }
    for (const auto& bx : boxes) {
      double t0 = 0, t1 = std::numeric_limits<double>::infinity();
      int axis = -1;
      bool hit = true;
      for (int a = 0; a < 3 && hit; ++a) {
        if (std::abs(d[a]) < 1e-15) {
          hit = o[a] >= bx.lo[a] && o[a] <= bx.hi[a];
          continue;
        }
        double ta = (bx.lo[a] - o[a]) / d[a], tb = (bx.hi[a] - o[a]) / d[a];
        if (ta > tb) std::swap(ta, tb);
        if (ta > t0) t0 = ta, axis = a;
        t1 = std::min(t1, tb);
        hit = t0 <= t1;
      }
      if (hit && axis >= 0 && t0 > 0 && t0 < best) {
        best = t0;
        *n = Eigen::Vector3d::Zero();
        (*n)[axis] = d[axis] > 0 ? -1 : 1;
      }
    }
    return best;
  }

  // Range image (CV_32FC1, NaN where no surface or grazing) of `cam` at T_W_C.
  cv::Mat render(const CameraModel& cam, const Eigen::Isometry3d& T_W_C) const {
    cv::Mat depth(cam.height(), cam.width(), CV_32FC1, cv::Scalar(NAN));
#pragma omp parallel for schedule(dynamic, 4)
    for (int v = 0; v < cam.height(); ++v) {
      for (int u = 0; u < cam.width(); ++u) {
        Eigen::Vector3d ray;
        if (!cam.unproject(Eigen::Vector2d(u, v), &ray)) continue;
        const Eigen::Vector3d d = T_W_C.linear() * ray;
        Eigen::Vector3d n;
        const double t = cast(T_W_C.translation(), d, &n);
        if (std::isfinite(t) && std::abs(n.dot(d)) >= min_incidence_cos) {
          depth.at<float>(v, u) = static_cast<float>(t);
        }
      }
    }
    return depth;
  }
};

// Camera pose at `position` looking at `target` (optical frame: z forward, y down).
inline Eigen::Isometry3d lookAt(const Eigen::Vector3d& position, const Eigen::Vector3d& target) {
  const Eigen::Vector3d z = (target - position).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();  // right
  const Eigen::Vector3d y = z.cross(x);                                       // down
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = y;
  T.linear().col(2) = z;
  T.translation() = position;
  return T;
}

}  // namespace analytic
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_SIM_ANALYTIC_SCENE_H_
