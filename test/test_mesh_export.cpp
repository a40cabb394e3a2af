// Mesh export (TsdfMesher::indexedMesh / saveMeshPly): welded vertices,
// area-weighted normals, height colours, binary PLY. The truth is analytic: a
// sphere written into the map's voxels as its exact signed distance (no
// cameras), so every vertex must lie on the sphere, every normal along the
// radius, and the welded surface must be closed (each edge in exactly two
// faces, in opposite directions; Euler characteristic 2); colours and the
// hand-built meshes are checked against hand-computed values; the PLY is read
// back by its own header.
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <numeric>
#include <set>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>
#include <pcl/PolygonMesh.h>
#include <pcl/io/ply_io.h>
#include <pcl/kdtree/kdtree_flann.h>

#include "fisheye_mapping/core/tsdf/tsdf_map.h"
#include "fisheye_mapping/core/tsdf/tsdf_mesher.h"

namespace fisheye_mapping {
namespace {

namespace fs = std::filesystem;
using Rgb = std::array<uint8_t, 3>;

// A sphere off the voxel grid (no voxel centre exactly on it), spanning
// several blocks on every axis.
const Eigen::Vector3d kCentre(0.013, -0.021, 1.037);
constexpr double kRadius = 1.0;

// The map with the sphere's signed distance (positive outside: the free
// space a camera would see, as the integrator writes it) in every voxel of
// the blocks around it, observed 10 times.
std::unique_ptr<TsdfMap> sphereMap() {
  TsdfConfig cfg;  // 5 cm voxels, truncation 4 voxels
  auto map = std::make_unique<TsdfMap>(cfg);
  const double bs = cfg.blockSize(), mu = cfg.truncation();
  BlockSet touched;
  const Eigen::Vector3i lo = ((kCentre.array() - kRadius - 2 * mu) / bs).floor().cast<int>();
  const Eigen::Vector3i hi = ((kCentre.array() + kRadius + 2 * mu) / bs).floor().cast<int>();
  for (int z = lo.z(); z <= hi.z(); ++z)
    for (int y = lo.y(); y <= hi.y(); ++y)
      for (int x = lo.x(); x <= hi.x(); ++x) touched.insert(BlockIndex(x, y, z));
  size_t allocated = 0, swapped_in = 0;
  for (auto& [b, block] : map->store().allocate(touched, &allocated, &swapped_in)) {
    for (int k = 0; k < FM_BLOCK_SIDE; ++k)
      for (int j = 0; j < FM_BLOCK_SIDE; ++j)
        for (int i = 0; i < FM_BLOCK_SIDE; ++i) {
          const Eigen::Vector3d p = map->voxelCenter(b * FM_BLOCK_SIDE + Eigen::Vector3i(i, j, k));
          const double d = std::clamp(((p - kCentre).norm() - kRadius) / mu, -1.0, 1.0);
          block->voxels[VoxelBlock::linear(i, j, k)] = FmVoxel{static_cast<float>(d), 10.0f};
        }
  }
  return map;
}

// The mesher's output for the sphere, built once.
class SphereMesh : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    map_ = sphereMap().release();
    mesher_ = new TsdfMesher(3);
    mesher_->rebuild(*map_);
  }
  static void TearDownTestSuite() {
    delete mesher_;
    delete map_;
  }
  static TsdfMap* map_;
  static TsdfMesher* mesher_;
};
TsdfMap* SphereMesh::map_ = nullptr;
TsdfMesher* SphereMesh::mesher_ = nullptr;

// The hue (degrees) of an 8-bit colour, by the textbook formula.
double hue(const Rgb& c) {
  const double r = c[0], g = c[1], b = c[2];
  const double mx = std::max({r, g, b}), mn = std::min({r, g, b});
  if (mx == mn) return 0;
  double h = mx == r ? (g - b) / (mx - mn) : mx == g ? 2 + (b - r) / (mx - mn) : 4 + (r - g) / (mx - mn);
  h *= 60;
  return h < 0 ? h + 360 : h;
}

TEST_F(SphereMesh, VerticesAreWeldedAcrossCubesAndBlocks) {
  std::set<std::tuple<float, float, float>> distinct;
  size_t soup = 0;
  std::set<std::tuple<int, int, int>> blocks;
  for (const auto& [b, out] : mesher_->blocks()) {
    soup += out.triangles.size();
    if (!out.triangles.empty()) blocks.insert({b.x(), b.y(), b.z()});
    for (const auto& p : out.triangles) distinct.insert({p.x() + 0.0f, p.y() + 0.0f, p.z() + 0.0f});
  }
  const IndexedMesh mesh = mesher_->indexedMesh();
  std::printf("sphere: %zu blocks with triangles, %zu soup vertices, %zu welded vertices, %zu faces\n",
              blocks.size(), soup, mesh.vertices.size(), mesh.faces.size());
  ASSERT_GT(blocks.size(), 50u);  // the surface crosses many block borders
  EXPECT_EQ(mesh.vertices.size(), distinct.size());
  EXPECT_EQ(mesh.faces.size() * 3, soup);  // no degenerate triangle on this sphere
  // No two vertices nearly coincide: the same grid edge always gave the same
  // bits (a 1 µm search finds each vertex alone).
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  for (const auto& v : mesh.vertices) cloud->push_back(pcl::PointXYZ(v.x(), v.y(), v.z()));
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(cloud);
  std::vector<int> idx;
  std::vector<float> d2;
  size_t crowded = 0;
  for (const auto& p : *cloud) crowded += tree.radiusSearch(p, 1e-6, idx, d2) > 1;
  EXPECT_EQ(crowded, 0u);
  // Every vertex on the sphere (linear interpolation of the exact distance:
  // well under a tenth of a voxel).
  double worst = 0;
  for (const auto& v : mesh.vertices) worst = std::max(worst, std::abs((v.cast<double>() - kCentre).norm() - kRadius));
  std::printf("largest distance of a vertex from the sphere: %.2e m\n", worst);
  EXPECT_LT(worst, 0.005);
}

TEST_F(SphereMesh, TheSurfaceIsClosedAndConsistentlyOriented) {
  const IndexedMesh mesh = mesher_->indexedMesh();
  // Directed edges: each once, and its reverse once (a closed, oriented
  // 2-manifold).
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const auto& f : mesh.faces) {
    for (int c = 0; c < 3; ++c) {
      ASSERT_LT(f[c], mesh.vertices.size());
      ASSERT_NE(f[c], f[(c + 1) % 3]);
      ++directed[{f[c], f[(c + 1) % 3]}];
    }
  }
  size_t bad = 0;
  for (const auto& [e, n] : directed) bad += n != 1 || directed.count({e.second, e.first}) == 0;
  EXPECT_EQ(bad, 0u);
  const long euler = static_cast<long>(mesh.vertices.size()) - static_cast<long>(directed.size() / 2) +
                     static_cast<long>(mesh.faces.size());
  EXPECT_EQ(euler, 2);  // a sphere's
  // Each face's winding normal points out of the sphere (into the free space).
  size_t inward = 0;
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
                          c = mesh.vertices[f[2]].cast<double>();
    inward += (b - a).cross(c - a).dot((a + b + c) / 3 - kCentre) <= 0;
  }
  EXPECT_EQ(inward, 0u);
}

TEST_F(SphereMesh, NormalsAreUnitAndRadial) {
  const IndexedMesh mesh = mesher_->indexedMesh();
  ASSERT_EQ(mesh.normals.size(), mesh.vertices.size());
  double min_dot = 1, max_len_err = 0;
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Eigen::Vector3d radial = (mesh.vertices[i].cast<double>() - kCentre).normalized();
    const Eigen::Vector3d n = mesh.normals[i].cast<double>();
    max_len_err = std::max(max_len_err, std::abs(n.norm() - 1));
    min_dot = std::min(min_dot, n.dot(radial));
  }
  std::printf("normals: smallest cosine to the radius %.4f, largest |norm - 1| %.1e\n", min_dot, max_len_err);
  EXPECT_LT(max_len_err, 1e-5);
  EXPECT_GT(min_dot, 0.9);
}

TEST_F(SphereMesh, HeightColoursFollowZ) {
  const IndexedMesh mesh = mesher_->indexedMesh();
  ASSERT_EQ(mesh.colors.size(), mesh.vertices.size());
  std::vector<size_t> order(mesh.vertices.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return mesh.vertices[a].z() < mesh.vertices[b].z(); });
  // Lowest blue, highest red (the ramp spans the mesh), hue never rising with z.
  EXPECT_EQ(mesh.colors[order.front()], (Rgb{0, 0, 255}));
  EXPECT_EQ(mesh.colors[order.back()], (Rgb{255, 0, 0}));
  size_t rises = 0;
  for (size_t n = 1; n < order.size(); ++n) rises += hue(mesh.colors[order[n]]) > hue(mesh.colors[order[n - 1]]);
  EXPECT_EQ(rises, 0u);
  // A fixed range: the sphere's equator (z = centre) is mid-ramp, green, for
  // the range centre +- 1; a range entirely below the mesh makes it all red.
  MeshExportOptions fixed;
  fixed.z_min = kCentre.z() - 1.0;
  fixed.z_max = kCentre.z() + 1.0;
  const IndexedMesh m2 = mesher_->indexedMesh(fixed);
  for (size_t i = 0; i < m2.vertices.size(); ++i) {
    if (std::abs(m2.vertices[i].z() - kCentre.z()) < 1e-3) {
      EXPECT_EQ(m2.colors[i], heightColor(0.5));
    }
  }
  fixed.z_min = -10, fixed.z_max = -5;
  for (const Rgb& c : mesher_->indexedMesh(fixed).colors) ASSERT_EQ(c, (Rgb{255, 0, 0}));
  MeshExportOptions none;
  none.coloring = MeshColoring::kNone;
  EXPECT_TRUE(mesher_->indexedMesh(none).colors.empty());
}

TEST(HeightColor, HandComputedRamp) {
  EXPECT_EQ(heightColor(0.0), (Rgb{0, 0, 255}));     // hue 240: blue
  EXPECT_EQ(heightColor(0.25), (Rgb{0, 255, 255}));  // hue 180: cyan
  EXPECT_EQ(heightColor(0.5), (Rgb{0, 255, 0}));     // hue 120: green
  EXPECT_EQ(heightColor(0.75), (Rgb{255, 255, 0}));  // hue 60: yellow
  EXPECT_EQ(heightColor(1.0), (Rgb{255, 0, 0}));     // hue 0: red
  EXPECT_EQ(heightColor(-3.0), heightColor(0.0));    // clamped
  EXPECT_EQ(heightColor(7.0), heightColor(1.0));
  EXPECT_EQ(heightColor(NAN), heightColor(0.0));
  for (int i = 1; i <= 1000; ++i) EXPECT_LE(hue(heightColor(i / 1000.0)), hue(heightColor((i - 1) / 1000.0))) << i;
}

TEST(WeldTriangles, HandBuiltSquare) {
  // The unit square in z = 0 as two counter-clockwise triangles (seen from
  // +z); the shared corner (1, 1) is written once as -0 z, which is +0.
  const std::vector<Eigen::Vector3f> soup = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0},  //
                                             {0, 0, 0}, {1, 1, -0.0f}, {0, 1, 0},
                                             // a degenerate triangle (two equal corners): dropped
                                             {0, 0, 0}, {5, 5, 5}, {5, 5, 5}};
  const IndexedMesh m = weldTriangles(soup);
  ASSERT_EQ(m.vertices.size(), 4u);  // (5, 5, 5) belongs to no face
  ASSERT_EQ(m.faces.size(), 2u);
  EXPECT_EQ(m.faces[0], (std::array<uint32_t, 3>{0, 1, 2}));
  EXPECT_EQ(m.faces[1], (std::array<uint32_t, 3>{0, 2, 3}));
  for (const auto& n : m.normals) EXPECT_EQ(n, Eigen::Vector3f(0, 0, 1));
  // Two faces of different areas at a vertex: their normals weighted by area.
  // Corner (0,0,0): a 1x1 triangle in z = 0 (normal +z, area 0.5) and a 2x2
  // one in x = 0 (normal +x, area 2): n = (2, 0, 0.5) / |.|.
  const IndexedMesh w = weldTriangles({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 0}, {0, 2, 0}, {0, 0, 2}});
  ASSERT_EQ(w.vertices.size(), 5u);
  EXPECT_TRUE(w.normals[0].isApprox(Eigen::Vector3f(2, 0, 0.5).normalized(), 1e-6f)) << w.normals[0].transpose();
  EXPECT_TRUE(w.normals[1].isApprox(Eigen::Vector3f(0, 0, 1), 1e-6f));
  // Heights 0 .. 2: colours at s = 0, 0, 0, 0, 1.
  EXPECT_EQ(w.colors[0], (Rgb{0, 0, 255}));
  EXPECT_EQ(w.colors[4], (Rgb{255, 0, 0}));
}

// A PLY file's header lines and the byte offset where its data begin.
struct PlyHeader {
  std::vector<std::string> lines;
  size_t data = 0;
};
PlyHeader readHeader(const std::string& bytes) {
  PlyHeader h;
  std::istringstream in(bytes);
  std::string line;
  while (std::getline(in, line)) {
    h.lines.push_back(line);
    if (line == "end_header") break;
  }
  h.data = static_cast<size_t>(in.tellg());
  return h;
}

std::string readBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

TEST_F(SphereMesh, PlyFileReadsBack) {
  char tmpl[] = "/tmp/fm_mesh_export_XXXXXX";
  const std::string dir = mkdtemp(tmpl);
  const std::string path = dir + "/sphere.ply";
  mesher_->saveMeshPly(path);
  const IndexedMesh mesh = mesher_->indexedMesh();
  const std::string bytes = readBytes(path);
  const PlyHeader h = readHeader(bytes);
  for (const auto& l : h.lines) std::printf("  %s\n", l.c_str());
  // The header, by its lines (comments aside).
  std::vector<std::string> lines;
  for (const auto& l : h.lines) {
    if (l.rfind("comment", 0) != 0 && l.rfind("obj_info", 0) != 0) lines.push_back(l);
  }
  const std::vector<std::string> expected = {"ply",
                                             "format binary_little_endian 1.0",
                                             "element vertex " + std::to_string(mesh.vertices.size()),
                                             "property float x",
                                             "property float y",
                                             "property float z",
                                             "property uchar red",
                                             "property uchar green",
                                             "property uchar blue",
                                             "property float nx",
                                             "property float ny",
                                             "property float nz",
                                             "element face " + std::to_string(mesh.faces.size()),
                                             "property list uchar int vertex_indices",
                                             "end_header"};
  EXPECT_EQ(lines, expected);
  // The data by that layout: 27-byte vertices, then 13-byte faces, nothing else.
  constexpr size_t kVertex = 3 * 4 + 3 + 3 * 4, kFace = 1 + 3 * 4;
  ASSERT_EQ(bytes.size(), h.data + mesh.vertices.size() * kVertex + mesh.faces.size() * kFace);
  size_t mismatches = 0;
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const char* p = bytes.data() + h.data + i * kVertex;
    float xyz[3], nrm[3];
    std::memcpy(xyz, p, 12);
    std::memcpy(nrm, p + 15, 12);
    const Rgb rgb = {static_cast<uint8_t>(p[12]), static_cast<uint8_t>(p[13]), static_cast<uint8_t>(p[14])};
    mismatches += Eigen::Vector3f(xyz[0], xyz[1], xyz[2]) != mesh.vertices[i] ||
                  Eigen::Vector3f(nrm[0], nrm[1], nrm[2]) != mesh.normals[i] || rgb != mesh.colors[i];
  }
  for (size_t f = 0; f < mesh.faces.size(); ++f) {
    const char* p = bytes.data() + h.data + mesh.vertices.size() * kVertex + f * kFace;
    int32_t idx[3];
    std::memcpy(idx, p + 1, 12);
    mismatches += p[0] != 3 || idx[0] != static_cast<int32_t>(mesh.faces[f][0]) ||
                  idx[1] != static_cast<int32_t>(mesh.faces[f][1]) || idx[2] != static_cast<int32_t>(mesh.faces[f][2]);
  }
  EXPECT_EQ(mismatches, 0u);
  // PCL's reader agrees on the counts.
  pcl::PolygonMesh back;
  ASSERT_EQ(pcl::io::loadPLYFile(path, back), 0);
  EXPECT_EQ(static_cast<size_t>(back.cloud.width) * back.cloud.height, mesh.vertices.size());
  EXPECT_EQ(back.polygons.size(), mesh.faces.size());

  // Without colours: no colour properties.
  MeshExportOptions none;
  none.coloring = MeshColoring::kNone;
  mesher_->saveMeshPly(path, none);
  const std::string plain = readBytes(path);
  EXPECT_EQ(plain.find("red"), std::string::npos);
  EXPECT_NE(plain.find("property float nx"), std::string::npos);
  EXPECT_THROW(mesher_->saveMeshPly(dir + "/no/such/dir/m.ply"), std::runtime_error);
  fs::remove_all(dir);
}

// The exports through the checked writer (issue 28): a link at the target is
// replaced, its target untouched; a FIFO is refused at once; a write that
// fails part-way (a file-size limit, as a full disk) throws naming the file
// and keeps the old one, with no temporary left.
TEST_F(SphereMesh, SavesNeverFollowALinkAndFailedWritesKeepTheOldFile) {
  char tmpl[] = "/tmp/fm_mesh_safe_XXXXXX";
  const std::string dir = mkdtemp(tmpl);
  std::ofstream(dir + "/victim") << "precious";
  fs::create_symlink(dir + "/victim", dir + "/mesh.ply");
  fs::create_symlink(dir + "/victim", dir + "/cloud.pcd");
  mesher_->saveMeshPly(dir + "/mesh.ply");
  mesher_->saveCloudPcd(dir + "/cloud.pcd");
  EXPECT_EQ(readBytes(dir + "/victim"), "precious");
  EXPECT_FALSE(fs::is_symlink(dir + "/mesh.ply"));
  EXPECT_EQ(readBytes(dir + "/mesh.ply").substr(0, 4), "ply\n");
  EXPECT_EQ(readBytes(dir + "/cloud.pcd").substr(0, 6), "# .PCD");

  ASSERT_EQ(mkfifo((dir + "/pipe.ply").c_str(), 0644), 0);
  try {
    mesher_->saveMeshPly(dir + "/pipe.ply");
    ADD_FAILURE() << "saved into a FIFO";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(dir + "/pipe.ply: is a FIFO"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(fs::is_fifo(dir + "/pipe.ply"));

  const std::string mesh_before = readBytes(dir + "/mesh.ply"), cloud_before = readBytes(dir + "/cloud.pcd");
  ASSERT_GT(mesh_before.size(), 64u * 1024);
  ASSERT_GT(cloud_before.size(), 16u * 1024);
  struct rlimit old_limit;
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old_limit), 0);
  struct rlimit small = old_limit;
  small.rlim_cur = 16 * 1024;
  signal(SIGXFSZ, SIG_IGN);  // writes then fail with EFBIG
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  std::string mesh_error, cloud_error;
  try {
    mesher_->saveMeshPly(dir + "/mesh.ply");
  } catch (const std::runtime_error& e) {
    mesh_error = e.what();
  }
  try {
    mesher_->saveCloudPcd(dir + "/cloud.pcd");
  } catch (const std::runtime_error& e) {
    cloud_error = e.what();
  }
  setrlimit(RLIMIT_FSIZE, &old_limit);
  signal(SIGXFSZ, SIG_DFL);
  EXPECT_NE(mesh_error.find(dir + "/mesh.ply"), std::string::npos) << "no error: " << mesh_error;
  EXPECT_NE(cloud_error.find(dir + "/cloud.pcd"), std::string::npos) << "no error: " << cloud_error;
  EXPECT_EQ(readBytes(dir + "/mesh.ply"), mesh_before);
  EXPECT_EQ(readBytes(dir + "/cloud.pcd"), cloud_before);
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"cloud.pcd", "mesh.ply", "pipe.ply", "victim"}));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace fisheye_mapping
