// Outputs of the TSDF map: an incremental marching-cubes mesh and the surface
// cloud of zero crossings, both from voxels observed at least
// min_observations times, kept per block so that only blocks changed since the
// last update are recomputed (and re-sent by the nodelet).
//
// Not thread-safe.
#ifndef FISHEYE_MAPPING_CORE_TSDF_TSDF_MESHER_H_
#define FISHEYE_MAPPING_CORE_TSDF_TSDF_MESHER_H_

#include <string>
#include <unordered_map>
#include <vector>

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "fisheye_mapping/core/tsdf/tsdf_map.h"

namespace fisheye_mapping {

struct BlockOutput {
  std::vector<Eigen::Vector3f> triangles;  // 3 vertices per triangle, world frame
  std::vector<Eigen::Vector3f> surface_points;
};

class TsdfMesher {
 public:
  explicit TsdfMesher(int min_observations) : min_observations_(min_observations) {}

  // Recomputes the blocks changed in `map` since the last call (and the
  // neighbours whose cubes reach into them). Returns the blocks whose output
  // changed (possibly to empty).
  std::vector<BlockIndex> update(TsdfMap& map);
  // Recomputes everything (e.g. after min_observations changed).
  std::vector<BlockIndex> rebuild(TsdfMap& map);

  const std::unordered_map<BlockIndex, BlockOutput, BlockIndexHash>& blocks() const { return blocks_; }
  size_t numTriangles() const;
  pcl::PointCloud<pcl::PointXYZ> surfaceCloud() const;

  // PLY mesh (binary) and PCD cloud (binary) through PCL. Throw
  // std::runtime_error naming the path on failure.
  void saveMeshPly(const std::string& path) const;
  void saveCloudPcd(const std::string& path) const;

  void clear() { blocks_.clear(); }
  void setMinObservations(int n) { min_observations_ = n; }

 private:
  // Reads only blocks already resident or fetched (BlockStore::find, no
  // I/O): safe in the parallel loop of recompute().
  BlockOutput computeBlock(const TsdfMap& map, const BlockIndex& index) const;
  std::vector<BlockIndex> recompute(TsdfMap& map, const BlockSet& dirty);

  int min_observations_;
  std::unordered_map<BlockIndex, BlockOutput, BlockIndexHash> blocks_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_TSDF_MESHER_H_
