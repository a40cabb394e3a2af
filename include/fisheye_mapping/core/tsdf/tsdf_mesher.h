// Outputs of the TSDF map: an incremental marching-cubes mesh and the surface
// cloud of zero crossings, both from voxels observed at least
// min_observations times, kept per block so that only blocks changed since the
// last update are recomputed (and re-sent by the nodelet).
//
// Every vertex lies on an edge of the voxel grid and is computed from that
// edge alone (its lower end, the two values), so the cubes and blocks sharing
// an edge produce bit-identical positions: exact position equality welds the
// triangle soup into an indexed mesh (IndexedMesh, the PLY export).
//
// Not thread-safe.
#ifndef FISHEYE_MAPPING_CORE_TSDF_TSDF_MESHER_H_
#define FISHEYE_MAPPING_CORE_TSDF_TSDF_MESHER_H_

#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "fisheye_mapping/core/tsdf/tsdf_map.h"

namespace fisheye_mapping {

struct BlockOutput {
  std::vector<Eigen::Vector3f> triangles;  // 3 vertices per triangle, world frame
  // The intensity at each vertex of `triangles` (same order): the grey of the
  // edge's two voxels interpolated at the crossing (one alone when the other
  // has none), 1..255; 0 = none (neither voxel has an intensity).
  std::vector<uint8_t> triangle_grey;
  std::vector<Eigen::Vector3f> surface_points;
  std::vector<uint8_t> surface_grey;  // the same for surface_points
};

struct MeshExportOptions {
  MeshColoring coloring = MeshColoring::kIntensity;
  // The z range (world frame, metres) spanned by the height ramp; values
  // outside are clamped. NaN: the mesh's own lowest and highest vertex.
  double z_min = NAN, z_max = NAN;
};

// A welded triangle mesh: shared vertices, unit area-weighted normals (sum of
// the adjacent faces' normals weighted by their areas, so pointing to the
// side the faces' counter-clockwise winding faces: out of the surface,
// towards the observed free space), and colours (empty for kNone).
struct IndexedMesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<uint8_t> grey;  // intensity per vertex (0 = none), as BlockOutput::triangle_grey
  std::vector<Eigen::Vector3f> normals;
  std::vector<std::array<uint8_t, 3>> colors;  // red, green, blue
  std::vector<std::array<uint32_t, 3>> faces;  // indices into vertices
};

// Welds a triangle soup (3 vertices per triangle) by exact position (-0 and
// +0 alike), drops triangles that collapse to a line or a point (a zero-area
// corner case of marching cubes), then adds normals and colours. `grey`: the
// intensity of each soup vertex (empty: none anywhere; then kIntensity
// colours by height).
IndexedMesh weldTriangles(const std::vector<Eigen::Vector3f>& triangles,
                          const MeshExportOptions& options = MeshExportOptions(),
                          const std::vector<uint8_t>& grey = {});

// The colour of one vertex: p its position, n its unit normal, grey its
// intensity (0 = none), z_lo..z_hi the height ramp's range (metres).
std::array<uint8_t, 3> vertexColor(MeshColoring coloring, const Eigen::Vector3f& p, const Eigen::Vector3f& n,
                                   uint8_t grey, double z_lo, double z_hi);

// The height ramp: s in [0, 1] (clamped; NaN as 0) to red, green, blue,
// hue falling from 240 degrees (blue) at 0 to 0 degrees (red) at 1, full
// saturation and value.
std::array<uint8_t, 3> heightColor(double s);

// Writes `mesh` as binary little-endian PLY through PCL: vertex x y z nx ny nz
// [red green blue] (float, uchar), face vertex_indices (list), checked for
// completeness and saved through writeFileSafely (core/common/safe_write.h:
// temporary file beside path, no link followed, FIFOs and devices refused,
// fsync, size and close checked). Throws std::runtime_error naming the path
// (and the OS error) on failure; the old file then stays as it was.
void saveIndexedMeshPly(const IndexedMesh& mesh, const std::string& path);

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
  // Surface points with their intensity (0: none).
  pcl::PointCloud<pcl::PointXYZI> surfaceCloud() const;

  // Every block's triangles welded into one mesh (weldTriangles).
  IndexedMesh indexedMesh(const MeshExportOptions& options = MeshExportOptions()) const;
  // PLY mesh (indexedMesh through saveIndexedMeshPly) and PCD cloud (binary)
  // through PCL, saved as saveIndexedMeshPly says. Throw std::runtime_error
  // naming the path (and the OS error) on failure.
  void saveMeshPly(const std::string& path, const MeshExportOptions& options = MeshExportOptions()) const;
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
