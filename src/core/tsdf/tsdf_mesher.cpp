#include "fisheye_mapping/core/tsdf/tsdf_mesher.h"

#include <pcl/PolygonMesh.h>
#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/surface/marching_cubes.h>  // Bourke's edge and triangle tables

#include <omp.h>

#include <array>

namespace fisheye_mapping {
namespace {

// Cube corners in the order of PCL's tables (see pcl/surface/marching_cubes.h).
constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1},
                               {0, 1, 0}, {1, 1, 0}, {1, 1, 1}, {0, 1, 1}};
constexpr int kEdge[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                              {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
constexpr int N = FM_BLOCK_SIDE + 1;  // the block plus one layer of its +x/+y/+z neighbours

Eigen::Vector3f interpolate(const Eigen::Vector3f& a, const Eigen::Vector3f& b, float va, float vb) {
  const float t = va / (va - vb);
  return a + t * (b - a);
}

}  // namespace

BlockOutput TsdfMesher::computeBlock(const TsdfMap& map, const BlockIndex& index) const {
  BlockOutput out;
  // Gather the (N)^3 voxel values; NaN marks voxels not observed often enough.
  std::array<float, N * N * N> val;
  const VoxelBlock* nb[2][2][2];
  for (int dz = 0; dz < 2; ++dz)
    for (int dy = 0; dy < 2; ++dy)
      for (int dx = 0; dx < 2; ++dx) nb[dz][dy][dx] = map.store().find(index + BlockIndex(dx, dy, dz));
  if (!nb[0][0][0]) return out;
  const float min_w = static_cast<float>(min_observations_);
  auto at = [&](int i, int j, int k) -> float& { return val[i + N * (j + N * k)]; };
  for (int k = 0; k < N; ++k) {
    for (int j = 0; j < N; ++j) {
      for (int i = 0; i < N; ++i) {
        const VoxelBlock* b = nb[k / FM_BLOCK_SIDE][j / FM_BLOCK_SIDE][i / FM_BLOCK_SIDE];
        float v = NAN;
        if (b) {
          const FmVoxel& vox =
              b->voxels[VoxelBlock::linear(i % FM_BLOCK_SIDE, j % FM_BLOCK_SIDE, k % FM_BLOCK_SIDE)];
          if (vox.weight >= min_w) v = vox.tsdf;
        }
        at(i, j, k) = v;
      }
    }
  }
  const float vs = static_cast<float>(map.config().voxel_size);
  const Eigen::Vector3f origin = ((index * FM_BLOCK_SIDE).cast<float>() + Eigen::Vector3f::Constant(0.5f)) * vs;
  auto position = [&](int i, int j, int k) -> Eigen::Vector3f { return origin + Eigen::Vector3f(i, j, k) * vs; };

  for (int k = 0; k < FM_BLOCK_SIDE; ++k) {
    for (int j = 0; j < FM_BLOCK_SIDE; ++j) {
      for (int i = 0; i < FM_BLOCK_SIDE; ++i) {
        // Surface points: zero crossings towards +x, +y, +z.
        const float v0 = at(i, j, k);
        if (v0 == v0) {
          const int nbr[3][3] = {{i + 1, j, k}, {i, j + 1, k}, {i, j, k + 1}};
          for (const auto& q : nbr) {
            const float v1 = at(q[0], q[1], q[2]);
            if (v1 == v1 && ((v0 < 0) != (v1 < 0))) {
              out.surface_points.push_back(
                  interpolate(position(i, j, k), position(q[0], q[1], q[2]), v0, v1));
            }
          }
        }
        // Marching cubes on the cube whose lowest corner is (i, j, k).
        float cv[8];
        bool complete = true;
        int cube = 0;
        for (int c = 0; c < 8 && complete; ++c) {
          cv[c] = at(i + kCorner[c][0], j + kCorner[c][1], k + kCorner[c][2]);
          complete = cv[c] == cv[c];
          if (cv[c] < 0.0f) cube |= 1 << c;
        }
        if (!complete || pcl::edgeTable[cube] == 0) continue;
        Eigen::Vector3f edge_vertex[12];
        for (int e = 0; e < 12; ++e) {
          if (pcl::edgeTable[cube] & (1 << e)) {
            const int a = kEdge[e][0], b = kEdge[e][1];
            edge_vertex[e] = interpolate(
                position(i + kCorner[a][0], j + kCorner[a][1], k + kCorner[a][2]),
                position(i + kCorner[b][0], j + kCorner[b][1], k + kCorner[b][2]), cv[a], cv[b]);
          }
        }
        for (int t = 0; pcl::triTable[cube][t] != -1; t += 3) {
          out.triangles.push_back(edge_vertex[pcl::triTable[cube][t]]);
          out.triangles.push_back(edge_vertex[pcl::triTable[cube][t + 1]]);
          out.triangles.push_back(edge_vertex[pcl::triTable[cube][t + 2]]);
        }
      }
    }
  }
  return out;
}

std::vector<BlockIndex> TsdfMesher::recompute(TsdfMap& map, const BlockSet& dirty) {
  std::vector<BlockIndex> list(dirty.begin(), dirty.end());
  // Read every block (and neighbour) once here: blocks swapped to disk are
  // loaded into the store's read cache, so the parallel loop below only makes
  // const lookups (BlockStore::find, no I/O).
  for (const BlockIndex& b : list) {
    for (int d = 0; d < 8; ++d) map.block(b + BlockIndex(d & 1, (d >> 1) & 1, d >> 2));
  }
  std::vector<BlockOutput> results(list.size());
  // The map's threads (TsdfConfig::threads, 0: the OpenMP default), as a
  // clause: the process-wide OpenMP setting is left alone.
  const int threads = map.config().threads > 0 ? map.config().threads : omp_get_max_threads();
#pragma omp parallel for num_threads(threads) schedule(dynamic, 4)
  for (size_t n = 0; n < list.size(); ++n) results[n] = computeBlock(map, list[n]);
  map.dropSwapCache();
  for (size_t n = 0; n < list.size(); ++n) {
    if (results[n].triangles.empty() && results[n].surface_points.empty()) {
      blocks_.erase(list[n]);
    } else {
      blocks_[list[n]] = std::move(results[n]);
    }
  }
  return list;
}

std::vector<BlockIndex> TsdfMesher::update(TsdfMap& map) {
  BlockSet dirty;
  for (const BlockIndex& b : map.takeChangedBlocks()) {
    // Cubes of the block and of its -x/-y/-z neighbours read this block's voxels.
    for (int dz = 0; dz < 2; ++dz)
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const BlockIndex n = b - BlockIndex(dx, dy, dz);
          if (map.block(n)) dirty.insert(n);
        }
  }
  return recompute(map, dirty);
}

std::vector<BlockIndex> TsdfMesher::rebuild(TsdfMap& map) {
  map.takeChangedBlocks();
  BlockSet all;
  for (const BlockIndex& b : map.allBlocks()) all.insert(b);
  for (const auto& kv : blocks_) all.insert(kv.first);
  blocks_.clear();
  return recompute(map, all);
}

size_t TsdfMesher::numTriangles() const {
  size_t n = 0;
  for (const auto& kv : blocks_) n += kv.second.triangles.size() / 3;
  return n;
}

pcl::PointCloud<pcl::PointXYZ> TsdfMesher::surfaceCloud() const {
  pcl::PointCloud<pcl::PointXYZ> cloud;
  for (const auto& kv : blocks_) {
    for (const auto& p : kv.second.surface_points) cloud.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  }
  return cloud;
}

void TsdfMesher::saveMeshPly(const std::string& path) const {
  pcl::PointCloud<pcl::PointXYZ> vertices;
  pcl::PolygonMesh mesh;
  for (const auto& kv : blocks_) {
    for (size_t t = 0; t + 2 < kv.second.triangles.size(); t += 3) {
      pcl::Vertices tri;
      for (int c = 0; c < 3; ++c) {
        const Eigen::Vector3f& p = kv.second.triangles[t + c];
        tri.vertices.push_back(static_cast<std::uint32_t>(vertices.size()));
        vertices.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
      }
      mesh.polygons.push_back(tri);
    }
  }
  pcl::toPCLPointCloud2(vertices, mesh.cloud);
  if (pcl::io::savePLYFileBinary(path, mesh) != 0) throw std::runtime_error(path + ": cannot write PLY mesh");
}

void TsdfMesher::saveCloudPcd(const std::string& path) const {
  const auto cloud = surfaceCloud();
  if (cloud.empty()) {
    throw std::runtime_error(path + ": the map has no surface point yet (nothing observed " +
                             std::to_string(min_observations_) + " times)");
  }
  if (pcl::io::savePCDFileBinary(path, cloud) != 0) throw std::runtime_error(path + ": cannot write PCD cloud");
}

}  // namespace fisheye_mapping
