// The sweep's planes (PlaneSweepConfig: fronto-parallel, ground, walls).
#include "fisheye_mapping/core/depth/plane_sweep.h"

namespace fisheye_mapping {

std::vector<FmSweepPlane> makeSweepPlanes(const PlaneSweepConfig& config, const Eigen::Isometry3d* T_base_ref) {
  std::vector<FmSweepPlane> planes;
  // Fronto-parallel: uniform in inverse depth, near to far.
  const double inv_near = 1.0 / config.near, inv_far = 1.0 / config.far;
  for (int i = 0; i < config.fronto_planes; ++i) {
    const double s = inv_near + (inv_far - inv_near) * i / (config.fronto_planes - 1);
    FmSweepPlane p{};
    p.nx = 0.0f;
    p.ny = 0.0f;
    p.nz = 1.0f;
    p.d = static_cast<float>(1.0 / s);
    p.family = FM_FAMILY_FRONTO;
    planes.push_back(p);
  }
  if (T_base_ref && config.ground_planes > 0) {
    // Plane z_base = h: e_z . (R X_ref + t) = h, i.e. n . X_ref = d with
    // n = -R^T e_z (pointing down, towards the ground) and d = t_z - h.
    const Eigen::Vector3d n = -(T_base_ref->linear().transpose() * Eigen::Vector3d::UnitZ());
    const double tz = T_base_ref->translation().z();
    for (int i = 0; i < config.ground_planes; ++i) {
      const double h = config.ground_height + config.ground_min +
                       (config.ground_max - config.ground_min) * i / (config.ground_planes - 1);
      const double d = tz - h;
      if (!(d > 0.0)) continue;  // plane at or above the camera: never seen from above
      FmSweepPlane p{};
      p.nx = static_cast<float>(n.x());
      p.ny = static_cast<float>(n.y());
      p.nz = static_cast<float>(n.z());
      p.d = static_cast<float>(d);
      p.family = FM_FAMILY_GROUND;
      planes.push_back(p);
    }
  }
  if (T_base_ref && config.wall_planes > 0) {
    // Plane y_base = +o (left) or -o (right): s e_y . (R X_ref + t) = o with
    // s = +1 / -1, i.e. n . X_ref = d with n = s R^T e_y (pointing from the
    // camera towards the wall) and d = o - s t_y. Uniform in 1 / o, nearest
    // first (as the fronto-parallel planes).
    const double inv_min = 1.0 / config.wall_min, inv_max = 1.0 / config.wall_max;
    for (const int side : {1, -1}) {
      const Eigen::Vector3d n = side * (T_base_ref->linear().transpose() * Eigen::Vector3d::UnitY());
      const double ty = T_base_ref->translation().y();
      for (int i = 0; i < config.wall_planes; ++i) {
        const double o = 1.0 / (inv_min + (inv_max - inv_min) * i / (config.wall_planes - 1));
        const double d = o - side * ty;
        if (!(d > 0.0)) continue;  // the camera is beyond this wall
        FmSweepPlane p{};
        p.nx = static_cast<float>(n.x());
        p.ny = static_cast<float>(n.y());
        p.nz = static_cast<float>(n.z());
        p.d = static_cast<float>(d);
        p.family = side > 0 ? FM_FAMILY_WALL_LEFT : FM_FAMILY_WALL_RIGHT;
        planes.push_back(p);
      }
    }
  }
  return planes;
}

}  // namespace fisheye_mapping
