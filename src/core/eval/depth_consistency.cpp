#include "fisheye_mapping/core/eval/depth_consistency.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Eigenvalues>

namespace fisheye_mapping {

namespace {

void checkImage(const cv::Mat& image, int type, const CameraModel& camera, const std::string& what) {
  if (image.type() != type || image.cols != camera.width() || image.rows != camera.height()) {
    throw std::invalid_argument(what + ": expected a " + std::to_string(camera.width()) + "x" +
                                std::to_string(camera.height()) + " image of type " + std::to_string(type) +
                                ", got " + std::to_string(image.cols) + "x" + std::to_string(image.rows) +
                                " of type " + std::to_string(image.type()));
  }
}

bool validRange(float r) { return std::isfinite(r) && r > 0.0f; }

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + mid, v.end());
  return v[mid];
}

// Plane n . p + d = 0 through the centroid of `pts` (indices `idx`), normal
// the smallest-eigenvalue direction of their scatter. False when degenerate.
bool fitPlaneLs(const std::vector<Eigen::Vector3d>& pts, const std::vector<size_t>& idx, Eigen::Vector3d* n,
                double* d) {
  if (idx.size() < 3) return false;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (size_t i : idx) c += pts[i];
  c /= static_cast<double>(idx.size());
  Eigen::Matrix3d s = Eigen::Matrix3d::Zero();
  for (size_t i : idx) {
    const Eigen::Vector3d q = pts[i] - c;
    s += q * q.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(s);
  if (es.info() != Eigen::Success) return false;
  *n = es.eigenvectors().col(0).normalized();  // eigenvalues ascending
  *d = -n->dot(c);
  return n->allFinite() && std::isfinite(*d);
}

}  // namespace

FrameConsistency frameConsistency(const cv::Mat& depth_a, const CameraModel& cam_a, const cv::Mat& depth_b,
                                  const CameraModel& cam_b, const Eigen::Isometry3d& T_a_b, double rel_tol) {
  checkImage(depth_a, CV_32FC1, cam_a, "frameConsistency: depth_a");
  checkImage(depth_b, CV_32FC1, cam_b, "frameConsistency: depth_b");
  const std::vector<Eigen::Vector3f> rays_b = pixelRays(cam_b);
  // Nearest point of b per pixel of a (range from camera a).
  cv::Mat zbuf(depth_a.size(), CV_32FC1, cv::Scalar(std::numeric_limits<float>::infinity()));
  for (int v = 0; v < depth_b.rows; ++v) {
    const float* row = depth_b.ptr<float>(v);
    for (int u = 0; u < depth_b.cols; ++u) {
      const float r = row[u];
      const Eigen::Vector3f& ray = rays_b[static_cast<size_t>(v) * depth_b.cols + u];
      if (!validRange(r) || !ray.allFinite()) continue;
      const Eigen::Vector3d p_a = T_a_b * (static_cast<double>(r) * ray.cast<double>());
      Eigen::Vector2d uv;
      if (!cam_a.project(p_a, &uv)) continue;
      const int ua = static_cast<int>(std::lround(uv.x())), va = static_cast<int>(std::lround(uv.y()));
      if (ua < 0 || va < 0 || ua >= depth_a.cols || va >= depth_a.rows) continue;
      float& z = zbuf.at<float>(va, ua);
      z = std::min(z, static_cast<float>(p_a.norm()));
    }
  }
  FrameConsistency out;
  std::vector<double> diffs;
  size_t agree = 0;
  for (int v = 0; v < depth_a.rows; ++v) {
    const float* ra = depth_a.ptr<float>(v);
    const float* rb = zbuf.ptr<float>(v);
    for (int u = 0; u < depth_a.cols; ++u) {
      if (!validRange(ra[u])) continue;
      ++out.valid_a;
      if (!std::isfinite(rb[u])) continue;
      const double diff = std::abs(static_cast<double>(ra[u]) - rb[u]) / ra[u];
      diffs.push_back(diff);
      if (diff <= rel_tol) ++agree;
    }
  }
  out.compared = diffs.size();
  out.share = out.compared ? static_cast<double>(agree) / out.compared : 0.0;
  out.median_rel_diff = median(std::move(diffs));
  return out;
}

Eigen::Isometry3d cameraGroundFrame(const Eigen::Isometry3d& T_base_cam, double ground_z) {
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d ahead = T_base_cam.linear().col(2);  // optical axis in the base frame
  ahead -= ahead.dot(up) * up;
  if (ahead.norm() < 1e-6) throw std::invalid_argument("cameraGroundFrame: the optical axis is vertical");
  ahead.normalize();
  Eigen::Isometry3d T_base_ground = Eigen::Isometry3d::Identity();
  T_base_ground.linear().col(0) = ahead;
  T_base_ground.linear().col(1) = up.cross(ahead);
  T_base_ground.linear().col(2) = up;
  const Eigen::Vector3d c = T_base_cam.translation();
  T_base_ground.translation() = Eigen::Vector3d(c.x(), c.y(), ground_z);
  return T_base_ground.inverse() * T_base_cam;
}

cv::Mat groundRegionMask(const CameraModel& camera, const Eigen::Isometry3d& T_ground_cam, const GroundBox& box) {
  const std::vector<Eigen::Vector3f> rays = pixelRays(camera);
  cv::Mat mask(camera.height(), camera.width(), CV_8UC1, cv::Scalar(0));
  const Eigen::Vector3d o = T_ground_cam.translation();
  for (int v = 0; v < mask.rows; ++v) {
    for (int u = 0; u < mask.cols; ++u) {
      const Eigen::Vector3f& ray = rays[static_cast<size_t>(v) * mask.cols + u];
      if (!ray.allFinite()) continue;
      const Eigen::Vector3d dir = T_ground_cam.linear() * ray.cast<double>();
      if (dir.z() > -1e-9) continue;  // parallel to or away from the ground
      const double t = -o.z() / dir.z();
      if (t <= 0) continue;
      const Eigen::Vector3d g = o + t * dir;
      if (g.x() >= box.x_min && g.x() <= box.x_max && g.y() >= box.y_min && g.y() <= box.y_max) {
        mask.at<uint8_t>(v, u) = 255;
      }
    }
  }
  return mask;
}

RoadFlatness roadPlaneFlatness(const cv::Mat& depth, const CameraModel& camera, const cv::Mat& mask, double tol) {
  checkImage(depth, CV_32FC1, camera, "roadPlaneFlatness: depth");
  if (!mask.empty()) checkImage(mask, CV_8UC1, camera, "roadPlaneFlatness: mask");
  const std::vector<Eigen::Vector3f> rays = pixelRays(camera);
  std::vector<Eigen::Vector3d> pts;
  for (int v = 0; v < depth.rows; ++v) {
    const float* row = depth.ptr<float>(v);
    for (int u = 0; u < depth.cols; ++u) {
      if (!mask.empty() && !mask.at<uint8_t>(v, u)) continue;
      const Eigen::Vector3f& ray = rays[static_cast<size_t>(v) * depth.cols + u];
      if (!validRange(row[u]) || !ray.allFinite()) continue;
      pts.push_back(static_cast<double>(row[u]) * ray.cast<double>());
    }
  }
  RoadFlatness out;
  out.points = pts.size();
  if (pts.size() < 3) return out;

  // RANSAC: hypotheses from 3 random points, scored on a fixed subsample.
  std::mt19937 rng(12345);
  std::uniform_int_distribution<size_t> pick(0, pts.size() - 1);
  std::vector<size_t> sample;
  const size_t sample_size = std::min<size_t>(pts.size(), 20000);
  for (size_t i = 0; i < sample_size; ++i) sample.push_back(sample_size == pts.size() ? i : pick(rng));
  Eigen::Vector3d best_n = Eigen::Vector3d::Zero();
  double best_d = 0.0;
  size_t best_count = 0;
  for (int it = 0; it < 500; ++it) {
    const Eigen::Vector3d& a = pts[pick(rng)];
    const Eigen::Vector3d& b = pts[pick(rng)];
    const Eigen::Vector3d& c = pts[pick(rng)];
    Eigen::Vector3d n = (b - a).cross(c - a);
    if (n.norm() < 1e-9) continue;
    n.normalize();
    const double d = -n.dot(a);
    size_t count = 0;
    for (size_t i : sample) count += std::abs(n.dot(pts[i]) + d) <= tol;
    if (count > best_count) best_count = count, best_n = n, best_d = d;
  }
  if (best_count == 0) return out;

  // Least-squares refits on the inliers of all points.
  auto inliersOf = [&](const Eigen::Vector3d& n, double d) {
    std::vector<size_t> idx;
    for (size_t i = 0; i < pts.size(); ++i) {
      if (std::abs(n.dot(pts[i]) + d) <= tol) idx.push_back(i);
    }
    return idx;
  };
  std::vector<size_t> inl = inliersOf(best_n, best_d);
  for (int it = 0; it < 3; ++it) {
    Eigen::Vector3d n;
    double d;
    if (!fitPlaneLs(pts, inl, &n, &d)) break;
    std::vector<size_t> next = inliersOf(n, d);
    if (next.size() < inl.size()) break;  // keep the better of the two
    best_n = n, best_d = d;
    const bool same = next.size() == inl.size();
    inl = std::move(next);
    if (same) break;
  }
  std::vector<double> dist;
  dist.reserve(pts.size());
  for (const auto& p : pts) dist.push_back(std::abs(best_n.dot(p) + best_d));
  out.inliers = inl.size();
  out.share = static_cast<double>(inl.size()) / pts.size();
  out.median_abs_dist = median(std::move(dist));
  out.normal = best_n;
  out.d = best_d;
  return out;
}

}  // namespace fisheye_mapping
