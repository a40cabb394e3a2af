// Which supporting views a sweep matches (parallax, overlap) and the sweep
// views of a rig's cameras.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "fisheye_mapping/core/depth/plane_sweep.h"

namespace fisheye_mapping {

std::vector<int> selectSupportViews(const PlaneSweepConfig& config, const CameraModel& ref,
                                    const std::vector<SweepView>& views, std::vector<std::string>* reasons) {
  // Reference pixels on a coarse grid, with the angle one pixel spans there.
  std::vector<Eigen::Vector3d> rays;
  std::vector<double> pixel_angle;
  for (int gy = 1; gy < 12; ++gy) {
    for (int gx = 1; gx < 16; ++gx) {
      const Eigen::Vector2d px(ref.width() * gx / 16.0, ref.height() * gy / 12.0);
      Eigen::Vector3d ray, next;
      if (ref.unproject(px, &ray) && ray.z() > 0.1 && ref.unproject(px + Eigen::Vector2d(1.0, 0.0), &next)) {
        rays.push_back(ray.normalized());
        pixel_angle.push_back(std::max(1e-9, std::acos(std::clamp(ray.normalized().dot(next.normalized()), -1.0, 1.0))));
      }
    }
  }
  const double mid = std::sqrt(config.near * config.far);
  std::vector<double> overlaps, per_plane;
  for (size_t i = 0; i < views.size(); ++i) {
    const SweepView& view = views[i];
    const Eigen::Isometry3d T_view_ref = view.T_ref_view.inverse();
    std::vector<double> parallax;
    int seen = 0;
    for (size_t k = 0; k < rays.size(); ++k) {
      const Eigen::Vector3d& ray = rays[k];
      Eigen::Vector2d a, b, m;
      // Fronto-parallel planes: z-depth near / far / mid along the ray.
      const Eigen::Vector3d pn = T_view_ref * (ray * (config.near / ray.z()));
      const Eigen::Vector3d pf = T_view_ref * (ray * (config.far / ray.z()));
      const bool pa = view.camera.project(pn, &a) && view.camera.isInImage(a);
      const bool pb = view.camera.project(pf, &b) && view.camera.isInImage(b);
      if (view.camera.project(T_view_ref * (ray * (mid / ray.z())), &m) && view.camera.isInImage(m)) ++seen;
      if (!(pa && pb)) continue;
      // In pixels of the coarser of the two images: a view with a longer
      // focal length (a narrow camera) has many of its own pixels of
      // parallax where the reference's window cannot resolve it.
      const double angle = std::acos(std::clamp(pn.normalized().dot(pf.normalized()), -1.0, 1.0));
      parallax.push_back(std::min((a - b).norm(), angle / pixel_angle[k]));
    }
    const double overlap = rays.empty() ? 0.0 : static_cast<double>(seen) / rays.size();
    double median = 0.0;
    if (!parallax.empty()) {
      std::nth_element(parallax.begin(), parallax.begin() + parallax.size() / 2, parallax.end());
      median = parallax[parallax.size() / 2];
    }
    overlaps.push_back(overlap);
    per_plane.push_back(median / std::max(1, config.fronto_planes - 1));
  }
  // The views that overlap enough; the largest parallax among them.
  double best = 0.0;
  for (size_t i = 0; i < views.size(); ++i) {
    if (overlaps[i] >= config.min_overlap) best = std::max(best, per_plane[i]);
  }
  std::vector<int> keep;
  for (size_t i = 0; i < views.size(); ++i) {
    std::ostringstream why;
    why.precision(3);
    if (overlaps[i] < config.min_overlap) {
      why << views[i].name << ": overlap " << overlaps[i] << " < min_overlap " << config.min_overlap;
    } else if (per_plane[i] < config.min_parallax_px) {
      why << views[i].name << ": parallax " << per_plane[i] << " px per plane < min_parallax_px "
          << config.min_parallax_px << " (baseline too small for the depth range)";
    } else if (per_plane[i] < config.min_parallax_ratio * best) {
      why << views[i].name << ": parallax " << per_plane[i] << " px per plane < min_parallax_ratio "
          << config.min_parallax_ratio << " x " << best
          << " of the best view (its cost curve is too flat to sharpen the mean; it would add noise and its "
             "calibration error)";
    } else {
      keep.push_back(static_cast<int>(i));
      continue;
    }
    if (reasons) reasons->push_back(why.str());
  }
  return keep;
}

SweepView rigSweepView(const Rig& rig, int index, int ref_index, const cv::Mat& image, const cv::Mat& mask) {
  const RigCamera& cam = rig.cameras.at(index);
  const RigCamera& ref = rig.cameras.at(ref_index);
  SweepView view;
  view.name = cam.name;
  view.camera = cam.model;
  view.T_ref_view = ref.T_cam0_cam.inverse() * cam.T_cam0_cam;
  view.image = image;
  view.mask = mask;
  return view;
}

}  // namespace fisheye_mapping
