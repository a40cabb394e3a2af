#include "fisheye_mapping/core/eval/mesh_distance.h"

#include <pcl/PolygonMesh.h>
#include <pcl/conversions.h>
#include <pcl/io/ply_io.h>
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_types.h>

#include <cmath>
#include <limits>
#include <stdexcept>

namespace fisheye_mapping {

Eigen::Vector3f closestPointOnTriangle(const Eigen::Vector3f& p, const Eigen::Vector3f& a, const Eigen::Vector3f& b,
                                       const Eigen::Vector3f& c) {
  const Eigen::Vector3f ab = b - a, ac = c - a, ap = p - a;
  const float d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3f bp = p - b;
  const float d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const float vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
  const Eigen::Vector3f cp = p - c;
  const float d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const float vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
  const float va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const float denom = 1.f / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

long long MeshDistance::key(int x, int y, int z) const {
  return ((long long)(x & 0x1FFFFF) << 42) | ((long long)(y & 0x1FFFFF) << 21) | (long long)(z & 0x1FFFFF);
}

MeshDistance::MeshDistance(std::vector<Eigen::Vector3f> vertices, std::vector<Eigen::Vector3i> faces,
                           float max_distance, float cell)
    : v_(std::move(vertices)), faces_(std::move(faces)), max_distance_(max_distance), cell_(cell) {
  if (!(max_distance > 0) || !(cell > 0)) throw std::invalid_argument("MeshDistance: distances must be positive");
  for (int f = 0; f < int(faces_.size()); ++f) {
    Eigen::Vector3f lo = v_.at(faces_[f][0]), hi = lo;
    for (int k = 1; k < 3; ++k) {
      lo = lo.cwiseMin(v_.at(faces_[f][k]));
      hi = hi.cwiseMax(v_.at(faces_[f][k]));
    }
    lo.array() -= max_distance_;
    hi.array() += max_distance_;
    const Eigen::Vector3i c0 = (lo / cell_).array().floor().cast<int>(), c1 = (hi / cell_).array().floor().cast<int>();
    const long long cells = (long long)(c1 - c0 + Eigen::Vector3i::Ones()).prod();
    if (cells > 50'000'000) throw std::runtime_error("MeshDistance: a triangle spans too many cells; use a larger cell");
    for (int x = c0.x(); x <= c1.x(); ++x)
      for (int y = c0.y(); y <= c1.y(); ++y)
        for (int z = c0.z(); z <= c1.z(); ++z) grid_[key(x, y, z)].push_back(f);
  }
}

MeshDistance MeshDistance::fromPly(const std::string& path, float max_distance, float cell) {
  pcl::PolygonMesh mesh;
  if (pcl::io::loadPLYFile(path, mesh) != 0 || mesh.polygons.empty())
    throw std::runtime_error(path + ": cannot read a triangle mesh from this PLY file");
  pcl::PointCloud<pcl::PointXYZ> cloud;
  pcl::fromPCLPointCloud2(mesh.cloud, cloud);
  std::vector<Eigen::Vector3f> v;
  v.reserve(cloud.size());
  for (const auto& p : cloud) v.emplace_back(p.x, p.y, p.z);
  std::vector<Eigen::Vector3i> f;
  for (const auto& poly : mesh.polygons) {
    for (size_t k = 2; k < poly.vertices.size(); ++k) {  // fan-triangulate polygons
      const Eigen::Vector3i t(poly.vertices[0], poly.vertices[k - 1], poly.vertices[k]);
      if (t.maxCoeff() >= int(v.size())) throw std::runtime_error(path + ": face refers to a missing vertex");
      f.push_back(t);
    }
  }
  return MeshDistance(std::move(v), std::move(f), max_distance, cell);
}

float MeshDistance::distance(const Eigen::Vector3f& p) const {
  const Eigen::Vector3i c = (p / cell_).array().floor().cast<int>();
  const auto it = grid_.find(key(c.x(), c.y(), c.z()));
  float best = std::numeric_limits<float>::infinity();
  if (it == grid_.end()) return best;
  for (int f : it->second) {
    const auto& t = faces_[f];
    const float d = (closestPointOnTriangle(p, v_[t[0]], v_[t[1]], v_[t[2]]) - p).norm();
    if (d < best) best = d;
  }
  return best <= max_distance_ ? best : std::numeric_limits<float>::infinity();
}

double MeshDistance::fractionWithin(const std::vector<Eigen::Vector3f>& points, float t) const {
  if (points.empty()) return 0.0;
  std::size_t n = 0;
#pragma omp parallel for reduction(+ : n)
  for (long i = 0; i < long(points.size()); ++i) n += distance(points[i]) <= t;
  return double(n) / points.size();
}

}  // namespace fisheye_mapping

namespace fisheye_mapping {

std::vector<float> nearestDistances(const std::vector<Eigen::Vector3f>& from, const std::vector<Eigen::Vector3f>& to) {
  std::vector<float> d(from.size(), std::numeric_limits<float>::infinity());
  if (to.empty()) return d;
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  cloud->reserve(to.size());
  for (const auto& p : to) cloud->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(cloud);
  std::vector<int> idx(1);
  std::vector<float> sq(1);
  for (size_t i = 0; i < from.size(); ++i)
    if (tree.nearestKSearch(pcl::PointXYZ(from[i].x(), from[i].y(), from[i].z()), 1, idx, sq) > 0) d[i] = std::sqrt(sq[0]);
  return d;
}

double shareWithin(const std::vector<float>& distances, float t) {
  if (distances.empty()) return 0.0;
  std::size_t n = 0;
  for (float v : distances) n += v <= t;
  return double(n) / distances.size();
}

}  // namespace fisheye_mapping
