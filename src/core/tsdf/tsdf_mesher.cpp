#include "fisheye_mapping/core/tsdf/tsdf_mesher.h"

#include <pcl/PolygonMesh.h>
#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/surface/marching_cubes.h>  // Bourke's edge and triangle tables

#include <omp.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <utility>

#include "fisheye_mapping/core/common/safe_write.h"

namespace fisheye_mapping {
namespace {

// The bytes a PCL writer (by file name, 0 on success) writes, in memory; its
// failures (a code, or pcl::IOException, which names no file) name `path`.
template <typename Save>
std::string pclOutput(const std::string& path, const char* what, Save save) {
  return captureFileOutput([&](const std::string& name) {
    int rc = -1;
    try {
      rc = save(name);
    } catch (const std::exception& e) {
      throw std::runtime_error(path + ": cannot write " + what + ": " + e.what());
    }
    if (rc != 0) throw std::runtime_error(path + ": cannot write " + what);
  });
}

// A file PCL wrote into memory: after its header (ending in `end_of_header`)
// exactly `body` bytes, else it is incomplete (std::runtime_error naming path).
void checkFileBody(const std::string& bytes, const std::string& end_of_header, size_t body, const std::string& path) {
  const size_t at = bytes.find(end_of_header);
  const size_t got = at == std::string::npos ? 0 : bytes.size() - at - end_of_header.size();
  if (at == std::string::npos || got != body) {
    throw std::runtime_error(path + ": the writer produced " + std::to_string(got) + " bytes of data, " +
                             std::to_string(body) + " expected; nothing saved");
  }
}

// Cube corners in the order of PCL's tables (see pcl/surface/marching_cubes.h).
constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1},
                               {0, 1, 0}, {1, 1, 0}, {1, 1, 1}, {0, 1, 1}};
constexpr int kEdge[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                              {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
constexpr int N = FM_BLOCK_SIDE + 1;  // the block plus one layer of its +x/+y/+z neighbours

// The zero crossing on the grid edge from global voxel g (value va) to its
// +axis neighbour (value vb), from the edge alone: every cube and block that
// shares the edge gets the same bits (in double, (g + 0.5 + t) is exact at
// t = 0 and t = 1, so a crossing on a corner matches from every edge there).
Eigen::Vector3f edgeCrossing(const Eigen::Vector3i& g, int axis, float va, float vb, double voxel_size) {
  const float t = va / (va - vb);
  Eigen::Vector3d p = g.cast<double>() + Eigen::Vector3d::Constant(0.5);
  p[axis] += t;
  return (p * voxel_size).cast<float>();
}

// The intensity at the zero crossing of an edge whose ends have values va, vb
// and intensities ga, gb (0 = none).
uint8_t edgeGrey(float va, float vb, uint8_t ga, uint8_t gb) {
  if (ga == 0) return gb;
  if (gb == 0) return ga;
  const float t = va / (va - vb);
  return static_cast<uint8_t>(std::lround(ga + t * (float(gb) - float(ga))));
}

// The axis along which edge e of a cube runs.
int edgeAxis(int e) {
  const int a = kEdge[e][0], b = kEdge[e][1];
  return kCorner[a][0] != kCorner[b][0] ? 0 : kCorner[a][1] != kCorner[b][1] ? 1 : 2;
}

}  // namespace

namespace {

// Exact position equality, with -0 and +0 alike (adding +0 turns -0 into +0).
struct PositionHash {
  size_t operator()(const Eigen::Vector3f& p) const {
    size_t h = 0;
    for (int a = 0; a < 3; ++a) {
      const float v = p[a] + 0.0f;
      uint32_t bits;
      std::memcpy(&bits, &v, sizeof(bits));
      h = h * 0x9E3779B97F4A7C15ull + bits;
    }
    return h;
  }
};
struct PositionEqual {
  bool operator()(const Eigen::Vector3f& a, const Eigen::Vector3f& b) const { return a == b; }
};

// Area-weighted vertex normals: the sum of the faces' cross products (twice
// their areas times their unit normals), normalized.
std::vector<Eigen::Vector3f> vertexNormals(const IndexedMesh& mesh) {
  std::vector<Eigen::Vector3f> n(mesh.vertices.size(), Eigen::Vector3f::Zero());
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3f& a = mesh.vertices[f[0]];
    const Eigen::Vector3f c = (mesh.vertices[f[1]] - a).cross(mesh.vertices[f[2]] - a);
    for (uint32_t v : f) n[v] += c;
  }
  for (auto& v : n) v.normalize();
  return n;
}

// The height ramp, one entry per degree of hue (240 at index 0 down to 0 at
// 240), converted once by OpenCV (HSV to RGB, float).
constexpr int kRampSteps = 240;
const std::array<std::array<uint8_t, 3>, kRampSteps + 1>& heightRamp() {
  static const std::array<std::array<uint8_t, 3>, kRampSteps + 1> ramp = [] {
    cv::Mat hsv(1, kRampSteps + 1, CV_32FC3), rgb;
    for (int i = 0; i <= kRampSteps; ++i) hsv.at<cv::Vec3f>(0, i) = cv::Vec3f(240.0f - i, 1.0f, 1.0f);
    cv::cvtColor(hsv, rgb, cv::COLOR_HSV2RGB);
    std::array<std::array<uint8_t, 3>, kRampSteps + 1> out;
    for (int i = 0; i <= kRampSteps; ++i) {
      for (int c = 0; c < 3; ++c) out[i][c] = cv::saturate_cast<uint8_t>(255.0f * rgb.at<cv::Vec3f>(0, i)[c]);
    }
    return out;
  }();
  return ramp;
}

}  // namespace

std::array<uint8_t, 3> vertexColor(MeshColoring coloring, const Eigen::Vector3f& p, const Eigen::Vector3f& n,
                                   uint8_t grey, double z_lo, double z_hi) {
  switch (coloring) {
    case MeshColoring::kIntensity:
      if (grey != 0) return {grey, grey, grey};
      break;  // no intensity: the height ramp
    case MeshColoring::kNormal: {
      std::array<uint8_t, 3> c;
      for (int a = 0; a < 3; ++a) {
        const float v = std::isfinite(n[a]) ? n[a] : 0.0f;
        c[a] = cv::saturate_cast<uint8_t>(std::lround(127.5f * (v + 1.0f)));
      }
      return c;
    }
    case MeshColoring::kNone: return {128, 128, 128};
    case MeshColoring::kHeight: break;
  }
  const double span = z_hi > z_lo ? z_hi - z_lo : 1.0;
  return heightColor((p.z() - z_lo) / span);
}

std::array<uint8_t, 3> heightColor(double s) {
  const double c = s > 0.0 ? std::min(s, 1.0) : 0.0;  // NaN -> 0
  return heightRamp()[static_cast<int>(std::lround(c * kRampSteps))];
}

IndexedMesh weldTriangles(const std::vector<Eigen::Vector3f>& triangles, const MeshExportOptions& options,
                          const std::vector<uint8_t>& grey) {
  if (!grey.empty() && grey.size() != triangles.size()) {
    throw std::invalid_argument("weldTriangles: " + std::to_string(grey.size()) + " intensities for " +
                                std::to_string(triangles.size()) + " vertices");
  }
  IndexedMesh mesh;
  std::unordered_map<Eigen::Vector3f, uint32_t, PositionHash, PositionEqual> index;
  index.reserve(triangles.size() / 2);
  mesh.faces.reserve(triangles.size() / 3);
  for (size_t t = 0; t + 2 < triangles.size(); t += 3) {
    const Eigen::Vector3f* p = &triangles[t];
    // Two corners on one point: no area, no face (and no vertex of its own).
    if (p[0] == p[1] || p[1] == p[2] || p[0] == p[2]) continue;
    std::array<uint32_t, 3> f;
    for (int c = 0; c < 3; ++c) {
      const auto [it, fresh] = index.emplace(p[c], static_cast<uint32_t>(mesh.vertices.size()));
      if (fresh) {
        mesh.vertices.push_back(p[c]);
        mesh.grey.push_back(grey.empty() ? 0 : grey[t + c]);
      }
      f[c] = it->second;
    }
    mesh.faces.push_back(f);
  }
  mesh.normals = vertexNormals(mesh);
  if (options.coloring != MeshColoring::kNone) {
    double lo = options.z_min, hi = options.z_max;
    if (std::isnan(lo) || std::isnan(hi)) {
      double mn = INFINITY, mx = -INFINITY;
      for (const auto& v : mesh.vertices) mn = std::min<double>(mn, v.z()), mx = std::max<double>(mx, v.z());
      if (std::isnan(lo)) lo = mn;
      if (std::isnan(hi)) hi = mx;
    }
    mesh.colors.reserve(mesh.vertices.size());
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      mesh.colors.push_back(vertexColor(options.coloring, mesh.vertices[i], mesh.normals[i], mesh.grey[i], lo, hi));
    }
  }
  return mesh;
}

void saveIndexedMeshPly(const IndexedMesh& mesh, const std::string& path) {
  const bool color = !mesh.colors.empty();
  pcl::PolygonMesh out;
  if (color) {
    pcl::PointCloud<pcl::PointXYZRGBNormal> cloud;
    cloud.resize(mesh.vertices.size());
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      auto& p = cloud[i];
      p.getVector3fMap() = mesh.vertices[i];
      p.getNormalVector3fMap() = mesh.normals[i];
      p.r = mesh.colors[i][0], p.g = mesh.colors[i][1], p.b = mesh.colors[i][2];
    }
    pcl::toPCLPointCloud2(cloud, out.cloud);
  } else {
    pcl::PointCloud<pcl::PointNormal> cloud;
    cloud.resize(mesh.vertices.size());
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      cloud[i].getVector3fMap() = mesh.vertices[i];
      cloud[i].getNormalVector3fMap() = mesh.normals[i];
    }
    pcl::toPCLPointCloud2(cloud, out.cloud);
  }
  // The writer takes each field at its offset: leaving curvature out of the
  // list leaves it out of the file.
  auto& fields = out.cloud.fields;
  fields.erase(std::remove_if(fields.begin(), fields.end(), [](const auto& f) { return f.name == "curvature"; }),
               fields.end());
  out.polygons.resize(mesh.faces.size());
  for (size_t f = 0; f < mesh.faces.size(); ++f) {
    out.polygons[f].vertices.assign(mesh.faces[f].begin(), mesh.faces[f].end());
  }
  // PCL writes by file name and does not check its stream: it writes into
  // memory, the body's size is checked against the mesh, and the bytes go to
  // the file through the checked writer.
  const std::string bytes =
      pclOutput(path, "PLY mesh", [&](const std::string& name) { return pcl::io::savePLYFileBinary(name, out); });
  const size_t vertex_bytes = 6 * sizeof(float) + (color ? 3 : 0), face_bytes = 1 + 3 * sizeof(int32_t);
  checkFileBody(bytes, "end_header\n", mesh.vertices.size() * vertex_bytes + mesh.faces.size() * face_bytes, path);
  writeFileSafely(path, bytes);
}

BlockOutput TsdfMesher::computeBlock(const TsdfMap& map, const BlockIndex& index) const {
  BlockOutput out;
  // Gather the (N)^3 voxel values; NaN marks voxels not observed often enough.
  std::array<float, N * N * N> val;
  std::array<uint8_t, N * N * N> gval;  // intensities, 0 = none
  const VoxelBlock* nb[2][2][2];
  for (int dz = 0; dz < 2; ++dz)
    for (int dy = 0; dy < 2; ++dy)
      for (int dx = 0; dx < 2; ++dx) nb[dz][dy][dx] = map.store().find(index + BlockIndex(dx, dy, dz));
  if (!nb[0][0][0]) return out;
  const float min_w = minObservationWeight(min_observations_);
  auto at = [&](int i, int j, int k) -> float& { return val[i + N * (j + N * k)]; };
  auto gat = [&](int i, int j, int k) -> uint8_t& { return gval[i + N * (j + N * k)]; };
  for (int k = 0; k < N; ++k) {
    for (int j = 0; j < N; ++j) {
      for (int i = 0; i < N; ++i) {
        const VoxelBlock* b = nb[k / FM_BLOCK_SIDE][j / FM_BLOCK_SIDE][i / FM_BLOCK_SIDE];
        float v = NAN;
        uint8_t g = 0;
        if (b) {
          const int l = VoxelBlock::linear(i % FM_BLOCK_SIDE, j % FM_BLOCK_SIDE, k % FM_BLOCK_SIDE);
          const FmVoxel& vox = b->voxels[l];
          if (vox.weight >= min_w) v = vox.tsdf, g = b->grey[l];
        }
        at(i, j, k) = v;
        gat(i, j, k) = g;
      }
    }
  }
  const double vs = map.config().voxel_size;
  const Eigen::Vector3i first = index * FM_BLOCK_SIDE;  // global index of local voxel (0, 0, 0)

  for (int k = 0; k < FM_BLOCK_SIDE; ++k) {
    for (int j = 0; j < FM_BLOCK_SIDE; ++j) {
      for (int i = 0; i < FM_BLOCK_SIDE; ++i) {
        // Surface points: zero crossings towards +x, +y, +z.
        const float v0 = at(i, j, k);
        if (v0 == v0) {
          const int nbr[3][3] = {{i + 1, j, k}, {i, j + 1, k}, {i, j, k + 1}};
          for (int axis = 0; axis < 3; ++axis) {
            const int* q = nbr[axis];
            const float v1 = at(q[0], q[1], q[2]);
            if (v1 == v1 && ((v0 < 0) != (v1 < 0))) {
              out.surface_points.push_back(edgeCrossing(first + Eigen::Vector3i(i, j, k), axis, v0, v1, vs));
              out.surface_grey.push_back(edgeGrey(v0, v1, gat(i, j, k), gat(q[0], q[1], q[2])));
            }
          }
        }
        // Marching cubes on the cube whose lowest corner is (i, j, k).
        float cv[8];
        uint8_t cg[8];
        bool complete = true;
        int cube = 0;
        for (int c = 0; c < 8 && complete; ++c) {
          cv[c] = at(i + kCorner[c][0], j + kCorner[c][1], k + kCorner[c][2]);
          cg[c] = gat(i + kCorner[c][0], j + kCorner[c][1], k + kCorner[c][2]);
          complete = cv[c] == cv[c];
          if (cv[c] < 0.0f) cube |= 1 << c;
        }
        if (!complete || pcl::edgeTable[cube] == 0) continue;
        Eigen::Vector3f edge_vertex[12];
        uint8_t edge_grey[12];
        for (int e = 0; e < 12; ++e) {
          if (pcl::edgeTable[cube] & (1 << e)) {
            // From the edge's lower corner, whatever the table's direction.
            const int axis = edgeAxis(e);
            int a = kEdge[e][0], b = kEdge[e][1];
            if (kCorner[a][axis] > kCorner[b][axis]) std::swap(a, b);
            const Eigen::Vector3i g = first + Eigen::Vector3i(i + kCorner[a][0], j + kCorner[a][1], k + kCorner[a][2]);
            edge_vertex[e] = edgeCrossing(g, axis, cv[a], cv[b], vs);
            edge_grey[e] = edgeGrey(cv[a], cv[b], cg[a], cg[b]);
          }
        }
        for (int t = 0; pcl::triTable[cube][t] != -1; ++t) {
          out.triangles.push_back(edge_vertex[pcl::triTable[cube][t]]);
          out.triangle_grey.push_back(edge_grey[pcl::triTable[cube][t]]);
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

pcl::PointCloud<pcl::PointXYZI> TsdfMesher::surfaceCloud() const {
  pcl::PointCloud<pcl::PointXYZI> cloud;
  for (const auto& kv : blocks_) {
    const BlockOutput& b = kv.second;
    for (size_t i = 0; i < b.surface_points.size(); ++i) {
      pcl::PointXYZI q;
      q.x = b.surface_points[i].x(), q.y = b.surface_points[i].y(), q.z = b.surface_points[i].z();
      q.intensity = b.surface_grey[i];
      cloud.push_back(q);
    }
  }
  return cloud;
}

IndexedMesh TsdfMesher::indexedMesh(const MeshExportOptions& options) const {
  std::vector<Eigen::Vector3f> soup;
  std::vector<uint8_t> grey;
  soup.reserve(numTriangles() * 3);
  grey.reserve(numTriangles() * 3);
  for (const auto& kv : blocks_) {
    soup.insert(soup.end(), kv.second.triangles.begin(), kv.second.triangles.end());
    grey.insert(grey.end(), kv.second.triangle_grey.begin(), kv.second.triangle_grey.end());
  }
  return weldTriangles(soup, options, grey);
}

void TsdfMesher::saveMeshPly(const std::string& path, const MeshExportOptions& options) const {
  saveIndexedMeshPly(indexedMesh(options), path);
}

void TsdfMesher::saveCloudPcd(const std::string& path) const {
  const auto cloud = surfaceCloud();
  if (cloud.empty()) {
    throw std::runtime_error(path + ": the map has no surface point yet (nothing observed " +
                             std::to_string(min_observations_) + " times)");
  }
  // As the PLY mesh: into memory, checked (x y z intensity, 4 floats a
  // point), then through the checked writer.
  const std::string bytes =
      pclOutput(path, "PCD cloud", [&](const std::string& name) { return pcl::io::savePCDFileBinary(name, cloud); });
  checkFileBody(bytes, "DATA binary\n", cloud.size() * 4 * sizeof(float), path);
  writeFileSafely(path, bytes);
}

}  // namespace fisheye_mapping
