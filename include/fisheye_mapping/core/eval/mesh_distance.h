// Exact point-to-mesh distances (no ROS), for checking a fused map against a
// ground-truth scene mesh (e.g. make_drive's static_scene.ply).
#ifndef FISHEYE_MAPPING_CORE_EVAL_MESH_DISTANCE_H_
#define FISHEYE_MAPPING_CORE_EVAL_MESH_DISTANCE_H_

#include <Eigen/Core>

#include <string>
#include <unordered_map>
#include <vector>

namespace fisheye_mapping {

class MeshDistance {
 public:
  /// Triangles as vertex triples. Distances are only resolved up to `max_distance`
  /// (farther points get +infinity); the triangle grid uses `cell` metres.
  MeshDistance(std::vector<Eigen::Vector3f> vertices, std::vector<Eigen::Vector3i> faces, float max_distance,
               float cell = 0.5f);
  /// Loads a triangle mesh PLY (PCL). Throws std::runtime_error naming the file.
  static MeshDistance fromPly(const std::string& path, float max_distance, float cell = 0.5f);

  /// Distance from p to the closest triangle, or +infinity when farther than max_distance.
  float distance(const Eigen::Vector3f& p) const;
  /// Share of points within t (<= max_distance) of the mesh.
  double fractionWithin(const std::vector<Eigen::Vector3f>& points, float t) const;
  std::size_t triangles() const { return faces_.size(); }

 private:
  std::vector<Eigen::Vector3f> v_;
  std::vector<Eigen::Vector3i> faces_;
  float max_distance_, cell_;
  std::unordered_map<long long, std::vector<int>> grid_;
  long long key(int x, int y, int z) const;
};

/// Closest point on triangle (a, b, c) to p (Ericson, Real-Time Collision Detection 5.1.5).
Eigen::Vector3f closestPointOnTriangle(const Eigen::Vector3f& p, const Eigen::Vector3f& a, const Eigen::Vector3f& b,
                                       const Eigen::Vector3f& c);

}  // namespace fisheye_mapping

namespace fisheye_mapping {

/// Distance from each point of `from` to its nearest neighbour in `to` (PCL kd-tree);
/// +infinity when `to` is empty.
std::vector<float> nearestDistances(const std::vector<Eigen::Vector3f>& from, const std::vector<Eigen::Vector3f>& to);

/// Share of distances <= t (0 for an empty list).
double shareWithin(const std::vector<float>& distances, float t);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_EVAL_MESH_DISTANCE_H_
