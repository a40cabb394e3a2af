// TSDF fusion of fisheye depth against analytic scenes (exact signed distance),
// and the map's bookkeeping: update rule, weight cap, swapping, save / load,
// bounded active memory, bad input.
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>

#include <gtest/gtest.h>

#include "fisheye_mapping/core/sim/analytic_scene.h"
#include "fisheye_mapping/core/common/opencl_context.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"
#include "fisheye_mapping/core/tsdf/tsdf_mesher.h"
#include "scratch_dir.h"
#include "test_utils.h"

namespace fisheye_mapping {
namespace {

using analytic::lookAt;
using analytic::Scene;

// The default rig's fisheye (unified, xi 0.98, radtan) at a quarter of the
// resolution, to keep the tests fast.
CameraModel smallFisheye() {
  return CameraModel::unified(test::makeIntrinsics(130, 130, 127.5, 67.5, 256, 136), 0.98, -0.02,
                              0.004, 2e-4, -1e-4);
}

Scene objectsScene() {
  Scene s;
  s.ground_extent = 8.0;
  s.spheres.push_back({Eigen::Vector3d(3.0, 0.9, 0.7), 0.7});
  s.boxes.push_back({Eigen::Vector3d(2.2, -1.6, 0.0), Eigen::Vector3d(3.6, -0.4, 0.8)});
  return s;
}

// 24 views on a circle of radius 4.5 m around the objects, 2.5 m high.
std::vector<Eigen::Isometry3d> orbit() {
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < 24; ++i) {
    const double a = 2 * M_PI * i / 24;
    poses.push_back(lookAt(Eigen::Vector3d(3 + 4.5 * std::cos(a), 4.5 * std::sin(a), 2.5),
                           Eigen::Vector3d(3, 0, 0.3)));
  }
  return poses;
}

// A fresh directory inside the program's scratch directory (removed when
// the program ends).
std::string tempDir() { return fisheye_mapping::test::freshScratchSubdir("/tmp/fm_tsdf_test_"); }

class Tsdf : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    config_ = new TsdfConfig();
    map_ = new TsdfMap(*config_);
    const CameraModel cam = smallFisheye();
    const Scene scene = objectsScene();
    // The vehicle stands on the ground below the camera.
    for (const auto& T : orbit()) {
      map_->integrate(scene.render(cam, T), cam, T, Eigen::Vector3d(T.translation().x(), T.translation().y(), 0));
    }
  }
  static void TearDownTestSuite() {
    delete map_;
    delete config_;
  }
  static TsdfConfig* config_;
  static TsdfMap* map_;
};
TsdfConfig* Tsdf::config_ = nullptr;
TsdfMap* Tsdf::map_ = nullptr;

TEST_F(Tsdf, TsdfMatchesTheSignedDistanceNearTheSurface) {
  const Scene scene = objectsScene();
  const double vs = config_->voxel_size, mu = config_->truncation();
  double sq = 0, sq_band = 0;
  size_t n = 0, n_band = 0;
  for (const BlockIndex& b : map_->allBlocks()) {
    const VoxelBlock* blk = map_->block(b);
    for (int k = 0; k < 8; ++k)
      for (int j = 0; j < 8; ++j)
        for (int i = 0; i < 8; ++i) {
          const FmVoxel& v = blk->voxels[VoxelBlock::linear(i, j, k)];
          if (v.weight < config_->min_observations) continue;
          const Eigen::Vector3d p = map_->voxelCenter(b * 8 + Eigen::Vector3i(i, j, k));
          const double truth = scene.sdf(p);
          if (std::abs(truth) >= mu) continue;
          const double err = v.tsdf * mu - truth;
          sq_band += err * err, ++n_band;
          // Projective distances stretch with the viewing angle away from the
          // surface; next to it (|sdf| < 1 voxel) they must be right.
          if (std::abs(truth) < vs) sq += err * err, ++n;
        }
  }
  const double rmse_near = std::sqrt(sq / n), rmse_band = std::sqrt(sq_band / n_band);
  std::cout << "voxels within 1 voxel of the surface: " << n << ", RMSE " << rmse_near / vs
            << " voxel; whole truncation band: " << n_band << ", RMSE " << rmse_band / vs << " voxel\n";
  EXPECT_GT(n, 20000u);
  EXPECT_LE(rmse_near, 0.5 * vs);
  EXPECT_LE(rmse_band, 1.0 * vs);
}

// True where the scene is not smooth: within the truncation distance (4
// voxels) of a box edge or of the junction of two shapes. Projective distances
// measured across a crease belong to the other surface, so a TSDF rounds
// creases off within its truncation band.
bool nearCrease(const Scene& scene, const Eigen::Vector3d& p, double voxel) {
  const double vs = 2.0 * voxel;  // 2 * vs = 4 voxels
  int close = 0;
  if (scene.ground && std::abs(p.z()) < 2 * vs) ++close;
  for (const auto& s : scene.spheres) close += std::abs((p - s.c).norm() - s.r) < 2 * vs;
  for (const auto& b : scene.boxes) {
    Scene only;
    only.ground = false;
    only.boxes.push_back(b);
    if (std::abs(only.sdf(p)) >= 2 * vs) continue;
    ++close;
    int faces = 0;
    for (int a = 0; a < 3; ++a) faces += std::min(std::abs(p[a] - b.lo[a]), std::abs(p[a] - b.hi[a])) < 2 * vs;
    if (faces >= 2) return true;
  }
  return close >= 2;
}

TEST_F(Tsdf, MeshVerticesLieOnTheTrueSurface) {
  TsdfMesher mesher(config_->min_observations);
  mesher.rebuild(*map_);
  const Scene scene = objectsScene();
  const double vs = config_->voxel_size;
  size_t n = 0, far = 0, smooth = 0, smooth_far = 0;
  double worst_smooth = 0;
  for (const auto& kv : mesher.blocks()) {
    for (const auto& v : kv.second.triangles) {
      const double e = std::abs(scene.sdf(v.cast<double>()));
      far += e > 0.5 * vs;
      ++n;
      if (!nearCrease(scene, v.cast<double>(), vs)) {
        ++smooth;
        smooth_far += e > 0.5 * vs;
        worst_smooth = std::max(worst_smooth, e);
      }
    }
  }
  std::cout << n / 3 << " triangles; " << far << " of " << n << " vertices beyond 0.5 voxel; on smooth parts "
            << smooth_far << " of " << smooth << ", worst " << worst_smooth / vs << " voxel\n";
  EXPECT_GT(n, 100000u);
  // Away from creases every vertex is within half a voxel of the surface;
  // at box edges and shape junctions the surface is rounded off by up to ~1.5 voxels.
  EXPECT_EQ(smooth_far, 0u);
  EXPECT_GT(smooth, n * 7 / 10);
  EXPECT_LE(far, n / 100);
  // The surface cloud too.
  const auto cloud = mesher.surfaceCloud();
  size_t cloud_far = 0;
  for (const auto& p : cloud) {
    const Eigen::Vector3d q(p.x, p.y, p.z);
    cloud_far += std::abs(scene.sdf(q)) > 0.5 * vs && !nearCrease(scene, q, vs);
  }
  EXPECT_GT(cloud.size(), 10000u);
  EXPECT_EQ(cloud_far, 0u);
}

TEST(TsdfUpdate, TruncationRuleAndWeightCap) {
  const float mu = 0.2f;
  FmVoxel v{0.0f, 0.0f};
  // Behind the surface by more than mu: untouched.
  EXPECT_EQ(fm_tsdf_update(&v, -0.2001f, mu, 3.0f), 0);
  EXPECT_EQ(v.weight, 0.0f);
  // Exactly -mu: D = -1.
  EXPECT_EQ(fm_tsdf_update(&v, -0.2f, mu, 3.0f), 1);
  EXPECT_FLOAT_EQ(v.tsdf, -1.0f);
  EXPECT_FLOAT_EQ(v.weight, 1.0f);
  // Far in front: clamped to 1. D = (1 * -1 + 1) / 2 = 0.
  fm_tsdf_update(&v, 5.0f, mu, 3.0f);
  EXPECT_FLOAT_EQ(v.tsdf, 0.0f);
  EXPECT_FLOAT_EQ(v.weight, 2.0f);
  // eta = 0.1: d = 0.5, D = (2 * 0 + 0.5) / 3 = 1/6, w = 3 (the cap).
  fm_tsdf_update(&v, 0.1f, mu, 3.0f);
  EXPECT_FLOAT_EQ(v.tsdf, 0.5f / 3.0f);
  EXPECT_FLOAT_EQ(v.weight, 3.0f);
  // At the cap the weight stays, and the average uses w = 3:
  // D = (3 * 1/6 + 1) / 4 = 0.375.
  fm_tsdf_update(&v, 1.0f, mu, 3.0f);
  EXPECT_FLOAT_EQ(v.tsdf, 0.375f);
  EXPECT_FLOAT_EQ(v.weight, 3.0f);
}

TEST(TsdfMap, WallIntegrationFollowsTheRule) {
  // A pinhole camera at the origin of the world looking along +x at a wall
  // x = 5 m. Along the optical axis the voxel at x has eta = 5 - x.
  TsdfConfig cfg;
  cfg.max_weight = 4;
  TsdfMap map(cfg);
  const CameraModel cam = CameraModel::pinhole(test::makeIntrinsics(100, 100, 63.5, 47.5, 128, 96));
  const Eigen::Isometry3d T_W_C = lookAt(Eigen::Vector3d(0, 0, 1.0), Eigen::Vector3d(5, 0, 1.0));
  Scene wall;
  wall.ground = false;
  wall.boxes.push_back({Eigen::Vector3d(5, -20, -20), Eigen::Vector3d(6, 20, 20)});
  const cv::Mat depth = wall.render(cam, T_W_C);
  for (int i = 0; i < 6; ++i) map.integrate(depth, cam, T_W_C, Eigen::Vector3d(0, 0, 0));
  const double vs = cfg.voxel_size, mu = cfg.truncation();
  // Voxel centres along the axis near (x, 0.025, 1.025) (y, z off by half a
  // voxel; the ray through them hits the wall at x = 5, so eta = 5 - x + O(1e-4)).
  int checked = 0;
  for (int gx = 90; gx < 110; ++gx) {
    const FmVoxel* v = map.voxel(Eigen::Vector3i(gx, 0, 20));
    const double x = (gx + 0.5) * vs;
    const double eta = 5.0 - x;
    if (eta < -mu) {
      EXPECT_TRUE(v == nullptr || v->weight == 0) << "voxel behind the band was updated, x " << x;
      continue;
    }
    // Blocks are allocated only within mu of the measurement.
    if (eta > mu && v == nullptr) continue;
    ASSERT_NE(v, nullptr) << x;
    EXPECT_EQ(v->weight, 4.0f) << x;  // six observations, capped at 4
    EXPECT_NEAR(v->tsdf, std::min(1.0, eta / mu), 2e-3) << x;
    ++checked;
  }
  EXPECT_GE(checked, 8);
}

// Intensity (issue 30): the grey of each pixel goes to the voxels near the
// surface it sees, averaged with the weight (capped at FM_GREY_MAX_WEIGHT).
// Truth: stripes painted on the wall by world y (the image value of a pixel is
// the stripe of the wall point its ray hits), and the running average by hand.
TEST(TsdfMap, IntensityFollowsThePaintOnTheWall) {
  const CameraModel cam = CameraModel::pinhole(test::makeIntrinsics(100, 100, 63.5, 47.5, 128, 96));
  const Eigen::Isometry3d T_W_C = lookAt(Eigen::Vector3d(0, 0, 1.0), Eigen::Vector3d(5, 0, 1.0));
  Scene wall;
  wall.ground = false;
  wall.boxes.push_back({Eigen::Vector3d(5, -20, -20), Eigen::Vector3d(6, 20, 20)});
  const cv::Mat depth = wall.render(cam, T_W_C);
  // Stripes 0.5 m wide: grey 40 where floor(2 y) is even, 220 where odd.
  auto paint = [](double y) { return (static_cast<int>(std::floor(2.0 * y)) % 2 == 0) ? 40 : 220; };
  cv::Mat grey(cam.height(), cam.width(), CV_8UC1);
  const std::vector<Eigen::Vector3f> rays = pixelRays(cam);
  for (int v = 0; v < cam.height(); ++v)
    for (int u = 0; u < cam.width(); ++u) {
      const Eigen::Vector3d p = T_W_C * (depth.at<float>(v, u) * rays[v * cam.width() + u].cast<double>());
      grey.at<uint8_t>(v, u) = static_cast<uint8_t>(paint(p.y()));
    }
  TsdfConfig cfg;
  TsdfMap map(cfg);
  map.integrate(depth, cam, T_W_C, Eigen::Vector3d::Zero(), {}, grey);
  TsdfMesher mesher(1);
  mesher.update(map);
  const IndexedMesh mesh = mesher.indexedMesh();
  ASSERT_GT(mesh.vertices.size(), 200u);
  size_t checked = 0, right = 0;
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const double y = mesh.vertices[i].y();
    const double frac = 2.0 * y - std::floor(2.0 * y);
    if (frac < 0.1 || frac > 0.9) continue;  // within 5 cm of a stripe edge
    ++checked;
    right += mesh.grey[i] == paint(y) && mesh.colors[i][0] == paint(y) && mesh.colors[i][2] == paint(y);
  }
  ASSERT_GT(checked, 100u);
  EXPECT_EQ(right, checked);
  // The average: a second view of grey 100 everywhere gives (1 * stripe + 100) / 2.
  map.integrate(depth, cam, T_W_C, Eigen::Vector3d::Zero(), {}, cv::Mat(grey.size(), CV_8UC1, cv::Scalar(100)));
  // A voxel right on the wall at y = 0.25 (stripe 40) and y = 0.75 (220); x = 5 is a voxel border: x index 99.
  const int on40 = map.grey(Eigen::Vector3i(99, 5, 20)), on220 = map.grey(Eigen::Vector3i(99, 15, 20));
  EXPECT_EQ(on40, 70);
  EXPECT_EQ(on220, 160);
  // Without an image the intensity stays; with a wrong one the frame is refused.
  map.integrate(depth, cam, T_W_C, Eigen::Vector3d::Zero());
  EXPECT_EQ(map.grey(Eigen::Vector3i(99, 5, 20)), 70);
  EXPECT_THROW(map.integrate(depth, cam, T_W_C, Eigen::Vector3d::Zero(), {}, cv::Mat(10, 10, CV_8UC1)),
               std::invalid_argument);
  EXPECT_THROW(map.integrate(depth, cam, T_W_C, Eigen::Vector3d::Zero(), {}, cv::Mat(grey.size(), CV_16UC1)),
               std::invalid_argument);
  // Normal colouring: the wall faces -x (towards the camera): red low, green and blue mid.
  MeshExportOptions normal;
  normal.coloring = MeshColoring::kNormal;
  const IndexedMesh coloured = mesher.indexedMesh(normal);
  size_t facing = 0;
  for (const auto& c : coloured.colors) facing += c[0] < 30 && std::abs(int(c[1]) - 128) < 30;
  EXPECT_GT(facing, coloured.colors.size() * 8 / 10);
}

TEST(TsdfUpdate, GreyAverageByHand) {
  unsigned char g = 0;
  fm_grey_update(&g, 0.0f, 200.0f);  // first: the value
  EXPECT_EQ(g, 200);
  fm_grey_update(&g, 1.0f, 100.0f);  // (1 * 200 + 100) / 2
  EXPECT_EQ(g, 150);
  fm_grey_update(&g, 2.0f, 0.0f);  // (2 * 150 + 0) / 3 = 100
  EXPECT_EQ(g, 100);
  fm_grey_update(&g, 50.0f, 255.0f);  // weight capped at 16: (16 * 100 + 255) / 17 = 109.1
  EXPECT_EQ(g, 109);
  unsigned char black = 0;
  fm_grey_update(&black, 0.0f, 0.0f);  // black is stored as 1: 0 means none
  EXPECT_EQ(black, 1);
}

// fm_tsdf_fuse (the branch-free update the CPU integrator vectorizes) against
// the rule by hand: the same values as fm_tsdf_update + fm_grey_update, and a
// voxel left bit-identical when there is no measurement or it is behind the
// band.
TEST(TsdfUpdate, FuseFollowsTheRuleByHandAndLeavesTheRestAlone) {
  const float mu = 0.2f, max_w = 3.0f;
  FmVoxel v{0.0f, 0.0f};
  unsigned char g = 0;
  // range 4.9 m, measured 5.0 m: eta 0.1, d 0.5; first grey is the value.
  EXPECT_EQ(fm_tsdf_fuse(&v, &g, 5.0f, 4.9f, 200.0f, mu, max_w, 1.0f), 1);
  EXPECT_NEAR(v.tsdf, 0.5f, 1e-5f);
  EXPECT_EQ(v.weight, 1.0f);
  EXPECT_EQ(g, 200);
  // eta -0.1 (in the band, behind): d -0.5, D = (0.5 - 0.5) / 2 = 0; grey (200 + 100) / 2.
  EXPECT_EQ(fm_tsdf_fuse(&v, &g, 5.0f, 5.1f, 100.0f, mu, max_w, 1.0f), 1);
  EXPECT_NEAR(v.tsdf, 0.0f, 1e-5f);
  EXPECT_EQ(v.weight, 2.0f);
  EXPECT_EQ(g, 150);
  // eta 1.0 (free space): d clamped to 1, D = 1/3; outside the band the grey is kept.
  EXPECT_EQ(fm_tsdf_fuse(&v, &g, 6.0f, 5.0f, 0.0f, mu, max_w, 1.0f), 1);
  EXPECT_NEAR(v.tsdf, 1.0f / 3.0f, 1e-5f);
  EXPECT_EQ(v.weight, 3.0f);
  EXPECT_EQ(g, 150);
  // No image (g < 0): the distance is fused, the grey kept; the weight stays at the cap.
  EXPECT_EQ(fm_tsdf_fuse(&v, &g, 5.0f, 5.0f, -1.0f, mu, max_w, 1.0f), 1);
  EXPECT_NEAR(v.tsdf, (3.0f / 3.0f + 0.0f) / 4.0f, 1e-5f);
  EXPECT_EQ(v.weight, 3.0f);
  EXPECT_EQ(g, 150);
  // Nothing to fuse: behind the band, NaN, inf, zero and negative ranges.
  const FmVoxel before = v;
  const float none[] = {4.7999f, std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                        0.0f, -3.0f};
  for (float measured : none) {
    EXPECT_EQ(fm_tsdf_fuse(&v, &g, measured, 5.0f, 10.0f, mu, max_w, 1.0f), 0) << measured;
    EXPECT_EQ(std::memcmp(&v, &before, sizeof(v)), 0) << measured;
    EXPECT_EQ(g, 150) << measured;
  }
  // Exactly -mu behind: fused as D = -1 (the rule's edge).
  FmVoxel e{0.0f, 0.0f};
  unsigned char ge = 0;
  EXPECT_EQ(fm_tsdf_fuse(&e, &ge, 5.0f, 5.2f, 50.0f, 0.2f, max_w, 1.0f), 1);
  EXPECT_NEAR(e.tsdf, -1.0f, 1e-4f);
  // A frame of observation weight 0.25 in free space (d = 1):
  // D = (1 * -1 + 0.25 * 1) / 1.25 = -0.6, w = 1.25.
  EXPECT_EQ(fm_tsdf_fuse(&e, &ge, 6.0f, 5.0f, 50.0f, 0.2f, max_w, 0.25f), 1);
  EXPECT_NEAR(e.tsdf, -0.6f, 1e-5f);
  EXPECT_FLOAT_EQ(e.weight, 1.25f);
}

// fm_tsdf_voxel_pixel: the nearest pixel of a point's projection, by hand with
// a pinhole camera (fx = fy = 100, centre (49.5, 29.5), 100 x 60 pixels).
TEST(TsdfUpdate, VoxelPixelIsTheNearestPixelInsideTheImage) {
  const CameraModel cam = CameraModel::pinhole(test::makeIntrinsics(100, 100, 49.5, 29.5, 100, 60));
  const FmCameraT<float> c = cam.floatParams();
  auto pixelOf = [&](double u, double v) {  // a point at z = 2 m projecting to (u, v)
    return fm_tsdf_voxel_pixel(&c, static_cast<float>((u - 49.5) / 100 * 2), static_cast<float>((v - 29.5) / 100 * 2),
                               2.0f);
  };
  EXPECT_EQ(pixelOf(10.2, 20.4), 20 * 100 + 10);
  EXPECT_EQ(pixelOf(10.6, 20.6), 21 * 100 + 11);
  EXPECT_EQ(pixelOf(-0.4, -0.4), 0);         // within half a pixel of the first
  EXPECT_EQ(pixelOf(99.4, 59.4), 59 * 100 + 99);
  EXPECT_EQ(pixelOf(-0.6, 10.0), -1);        // left of the image
  EXPECT_EQ(pixelOf(99.6, 10.0), -1);        // right of it
  EXPECT_EQ(pixelOf(10.0, 59.6), -1);        // below it
  EXPECT_EQ(fm_tsdf_voxel_pixel(&c, 0.0f, 0.0f, -2.0f), -1);  // behind the camera
  EXPECT_EQ(fm_tsdf_voxel_pixel(&c, 1e30f, 0.0f, 1e-30f), -1);  // far outside: no overflow
  EXPECT_EQ(fm_tsdf_voxel_pixel(&c, std::numeric_limits<float>::quiet_NaN(), 0.0f, 2.0f), -1);
}

// Allocation (the vectorized row samples): every pixel's surface point, computed
// here in double precision from the camera model, lies in an allocated block
// that integration then updated near the surface, for a fisheye frame with
// pixels outside the model's domain, NaN, inf and beyond max_range.
TEST(TsdfMap, EverySurfacePointLandsInAnAllocatedBlock) {
  TsdfConfig cfg;
  cfg.max_range = 3.0;
  TsdfMap map(cfg);
  const CameraModel cam = smallFisheye();
  const Eigen::Isometry3d T_W_C = lookAt(Eigen::Vector3d(-1.0, 0.4, 1.8), Eigen::Vector3d(3, 0, 0.3));
  cv::Mat depth = objectsScene().render(cam, T_W_C);
  for (int v = 0; v < depth.rows; v += 7) depth.at<float>(v, v % depth.cols) = std::numeric_limits<float>::infinity();
  for (int v = 3; v < depth.rows; v += 11) depth.at<float>(v, (2 * v) % depth.cols) = -1.0f;
  // The map's world is the scene's shifted off the block grid (the ground
  // plane z = 0 would lie on block faces).
  const Eigen::Isometry3d T_M_C = Eigen::Translation3d(0.13, 0.17, 0.21) * T_W_C;
  map.integrate(depth, cam, T_M_C, Eigen::Vector3d(0, 0, 0));
  const double block = cfg.blockSize();
  size_t checked = 0, missing = 0, beyond = 0, far = 0;
  for (int v = 0; v < depth.rows; ++v) {
    for (int u = 0; u < depth.cols; ++u) {
      const float d = depth.at<float>(v, u);
      Eigen::Vector3d ray;
      if (!(d > 0.0f) || !std::isfinite(d) || !cam.unproject(Eigen::Vector2d(u, v), &ray)) continue;
      const Eigen::Vector3d q = T_M_C * (ray.normalized() * d) / block;
      // Points within 1e-4 of a block face may fall either side in float.
      if (((q.array() - q.array().round()).abs() < 1e-4).any()) continue;
      const BlockIndex b(q.array().floor().cast<int>());
      if (d > cfg.max_range) {
        ++far;
        beyond += map.block(b) == nullptr;
        continue;
      }
      ++checked;
      missing += map.block(b) == nullptr;
    }
  }
  std::cout << checked << " surface points checked, " << missing << " outside the allocated blocks; " << beyond
            << " of " << far << " beyond max_range in blocks never allocated\n";
  EXPECT_GT(checked, 5000u);
  EXPECT_EQ(missing, 0u);
  EXPECT_GT(far, 1000u);
  EXPECT_GT(beyond, far / 2);  // some points beyond max_range fell in blocks nothing else touched
}

// A parked car that drove off (issue 31): a box fused as a car, then the wall
// behind it seen where it stood. Without a carve region the car stays in the
// map (no ray ends near it any more); with its region the space in front of
// the wall is carved free and only the wall is left.
TEST(TsdfMap, CarveRegionsLeaveNoGhost) {
  const CameraModel cam = CameraModel::pinhole(test::makeIntrinsics(100, 100, 63.5, 47.5, 128, 96));
  const Eigen::Isometry3d T_W_C = lookAt(Eigen::Vector3d(0, 0, 1.0), Eigen::Vector3d(5, 0, 1.0));
  Scene parked, gone;
  parked.ground = gone.ground = false;
  const analytic::Box wall{Eigen::Vector3d(10, -20, -20), Eigen::Vector3d(11, 20, 20)};
  parked.boxes = {wall, {Eigen::Vector3d(5, -1, 0), Eigen::Vector3d(9.5, 1, 1.5)}};
  gone.boxes = {wall};
  const cv::Mat with_car = parked.render(cam, T_W_C), without = gone.render(cam, T_W_C);
  auto nearCar = [&](TsdfMap& map) {
    TsdfMesher mesher(map.config().min_observations);
    mesher.rebuild(map);  // every block (update() takes only those changed since the last one)
    int n = 0;
    for (const auto& p : mesher.surfaceCloud().points) n += p.x < 9.7;  // the wall is at x = 10
    return n;
  };
  const Eigen::AlignedBox3d region(Eigen::Vector3d(4, -3, -1), Eigen::Vector3d(10, 3, 3));
  // Neither a carve region nor free-space carving; the region only; free-space
  // carving only (every active block seen in front of the wall).
  enum Mode { kNone, kRegion, kFreeSpace };
  for (const Mode mode : {kNone, kRegion, kFreeSpace}) {
    SCOPED_TRACE(mode);
    TsdfConfig cfg;
    cfg.free_space_carving = mode == kFreeSpace;
    TsdfMap map{cfg};
    for (int i = 0; i < 8; ++i) map.integrate(with_car, cam, T_W_C, Eigen::Vector3d(0, 0, 0));
    const int before = nearCar(map);
    EXPECT_GT(before, 200) << "the parked car is in the map";
    std::vector<Eigen::AlignedBox3d> regions;
    if (mode == kRegion) regions.push_back(region);
    size_t carved = 0;
    for (int i = 0; i < 12; ++i) carved += map.integrate(without, cam, T_W_C, Eigen::Vector3d(0, 0, 0), regions).blocks_carved;
    const int after = nearCar(map);
    if (mode == kNone) {
      EXPECT_GT(after, before / 2) << "without carving the ghost stays";
    } else {
      EXPECT_EQ(after, 0) << "the car's voxels in front of the wall are carved free";
    }
    // The car's blocks are 0.4 m: those whose centre lies more than mu + half
    // a diagonal (0.2 + 0.35 m) in front of the wall at x = 10, i.e. the car's
    // body from x = 5 to 9.45, are the carved ones.
    if (mode == kFreeSpace) {
      EXPECT_GT(carved, 12u * 20u);
    } else {
      EXPECT_EQ(carved, 0u);
    }
  }
}

// Free-space carving keeps what is there: orbiting the objects (exact depth),
// the blocks each view sees in front of the sphere, the box and the ground are
// fused too, and the surface stays as complete as without carving, every
// point away from the creases within half a voxel of the true surface.
TEST(TsdfMap, FreeSpaceCarvingKeepsTheTrueSurfaces) {
  const CameraModel cam = smallFisheye();
  const Scene scene = objectsScene();
  size_t counts[2];
  for (const bool carving : {false, true}) {
    SCOPED_TRACE(carving);
    TsdfConfig cfg;
    cfg.free_space_carving = carving;
    TsdfMap map(cfg);
    size_t carved = 0;
    for (const auto& T : orbit()) {
      carved += map.integrate(scene.render(cam, T), cam, T, Eigen::Vector3d(T.translation().x(), T.translation().y(), 0))
                    .blocks_carved;
    }
    TsdfMesher mesher(cfg.min_observations);
    mesher.rebuild(map);
    size_t off = 0;
    const auto cloud = mesher.surfaceCloud();
    for (const auto& p : cloud) {
      const Eigen::Vector3d q(p.x, p.y, p.z);
      off += std::abs(scene.sdf(q)) > 0.5 * cfg.voxel_size && !nearCrease(scene, q, cfg.voxel_size);
    }
    counts[carving] = cloud.size();
    EXPECT_EQ(off, 0u);
    if (carving) {
      EXPECT_GT(carved, 0u) << "blocks seen in front of the surfaces from the other side of the orbit";
    } else {
      EXPECT_EQ(carved, 0u);
    }
  }
  EXPECT_GT(counts[0], 10000u);
  EXPECT_GE(counts[1], counts[0] * 0.99) << "carving must not eat the true surfaces";
  EXPECT_LE(counts[1], counts[0] * 1.01);
}

// Drive past walls along x: ground and two facades at y = +-6 m.
Scene street() {
  Scene s;
  s.boxes.push_back({Eigen::Vector3d(-1e3, 6, 0), Eigen::Vector3d(1e4, 7, 8)});
  s.boxes.push_back({Eigen::Vector3d(-1e3, -7, 0), Eigen::Vector3d(1e4, -6, 8)});
  s.min_incidence_cos = 0.2;
  return s;
}

Eigen::Isometry3d carCamera(double x) {
  return lookAt(Eigen::Vector3d(x, 0, 1.6), Eigen::Vector3d(x + 10, 0, 0.6));
}

// 10 cm voxels and a 20 x 20 x 3 m local map: blocks leave it within metres.
TsdfConfig smallLocalMap() {
  TsdfConfig cfg;
  cfg.voxel_size = 0.1;
  cfg.local_map_size = Eigen::Vector3d(20, 20, 3);
  return cfg;
}

TEST(TsdfMap, ActiveMemoryStaysBoundedOnALongDrive) {
  TsdfMap map(smallLocalMap());
  const CameraModel cam = smallFisheye();
  const Scene s = street();
  // Blocks of 0.8 m: the box holds at most (20/0.8 + 1)^2 * (3/0.8 + 1) blocks.
  const size_t bound = 26 * 26 * 5;
  size_t max_active = 0, active_at_100m = 0;
  for (double x = 0; x <= 400; x += 2.0) {
    const Eigen::Isometry3d T = carCamera(x);
    map.integrate(s.render(cam, T), cam, T, Eigen::Vector3d(x, 0, 0));
    max_active = std::max(max_active, map.numActiveBlocks());
    if (x == 100) active_at_100m = map.numActiveBlocks();
  }
  std::cout << "active blocks: max " << max_active << ", at 100 m " << active_at_100m
            << ", at 400 m " << map.numActiveBlocks() << "; all blocks " << map.numBlocks() << "\n";
  EXPECT_LE(max_active, bound);
  // The stored map keeps growing with the drive while the active part does not.
  EXPECT_GT(map.numBlocks(), 8 * max_active);
  EXPECT_LT(map.numActiveBlocks(), active_at_100m * 1.3);
}

void expectSameBlocks(const TsdfMap& a, const std::map<std::tuple<int, int, int>, VoxelBlock>& snapshot) {
  ASSERT_EQ(a.numBlocks(), snapshot.size());
  for (const auto& kv : snapshot) {
    const auto& [x, y, z] = kv.first;
    const VoxelBlock* b = a.block(BlockIndex(x, y, z));
    ASSERT_NE(b, nullptr);
    EXPECT_EQ(std::memcmp(b->voxels.data(), kv.second.voxels.data(), sizeof(b->voxels)), 0);
  }
}

std::map<std::tuple<int, int, int>, VoxelBlock> snapshot(const TsdfMap& map) {
  std::map<std::tuple<int, int, int>, VoxelBlock> out;
  for (const BlockIndex& b : map.allBlocks()) out[{b.x(), b.y(), b.z()}] = *map.block(b);
  return out;
}

class TsdfSwap : public ::testing::TestWithParam<bool> {};

TEST_P(TsdfSwap, SwapOutThenInIsBitIdentical) {
  TsdfConfig cfg = smallLocalMap();
  const std::string dir = tempDir();
  if (GetParam()) cfg.swap_directory = dir + "/swap";
  TsdfMap map(cfg);
  const CameraModel cam = smallFisheye();
  const Scene s = street();
  for (double x = 0; x <= 10; x += 2.0) {
    map.integrate(s.render(cam, carCamera(x)), cam, carCamera(x), Eigen::Vector3d(x, 0, 0));
  }
  const auto before = snapshot(map);
  const size_t active = map.numActiveBlocks();
  ASSERT_GT(active, 100u);
  // Drive far away: everything leaves the local map...
  EXPECT_EQ(map.moveLocalMap(Eigen::Vector3d(1000, 0, 0)), active);
  EXPECT_EQ(map.numActiveBlocks(), 0u);
  EXPECT_EQ(map.numSwappedBlocks(), before.size());
  expectSameBlocks(map, before);  // readable while swapped
  map.dropSwapCache();
  // ...and come back: the same blocks return, bit for bit.
  map.moveLocalMap(Eigen::Vector3d(10, 0, 0));
  EXPECT_EQ(map.numActiveBlocks(), active);
  expectSameBlocks(map, before);
  std::system(("rm -rf " + dir).c_str());
}

INSTANTIATE_TEST_SUITE_P(MemoryAndDisk, TsdfSwap, ::testing::Values(false, true),
                         [](const auto& info) { return info.param ? "disk" : "memory"; });

TEST(TsdfMap, SaveThenLoadIsBitIdenticalAndBadFilesChangeNothing) {
  const TsdfConfig cfg = smallLocalMap();
  TsdfMap map(cfg);
  const CameraModel cam = smallFisheye();
  const Scene s = street();
  for (double x = 0; x <= 40; x += 4.0) {
    map.integrate(s.render(cam, carCamera(x)), cam, carCamera(x), Eigen::Vector3d(x, 0, 0));
  }
  ASSERT_GT(map.numSwappedBlocks(), 0u);  // both stores are saved
  const auto before = snapshot(map);
  const std::string dir = tempDir();
  map.save(dir + "/map.fmtsdf");
  TsdfMap loaded(cfg);
  loaded.load(dir + "/map.fmtsdf");
  expectSameBlocks(loaded, before);

  // A truncated file: clear error, the map it was loaded into is untouched.
  {
    std::ifstream in(dir + "/map.fmtsdf", std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(dir + "/cut.fmtsdf", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
    std::ofstream(dir + "/junk.fmtsdf") << "not a map";
  }
  try {
    loaded.load(dir + "/cut.fmtsdf");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("truncated map file"), std::string::npos) << e.what();
  }
  expectSameBlocks(loaded, before);
  EXPECT_THROW(loaded.load(dir + "/junk.fmtsdf"), std::runtime_error);
  EXPECT_THROW(loaded.load(dir + "/missing.fmtsdf"), std::runtime_error);
  TsdfConfig other = cfg;
  other.voxel_size = 0.05;
  TsdfMap wrong(other);
  EXPECT_THROW(wrong.load(dir + "/map.fmtsdf"), std::runtime_error);
  expectSameBlocks(loaded, before);
  std::system(("rm -rf " + dir).c_str());
}

TEST(TsdfMap, OpenClIntegratorAgreesWithCpu) {
  if (OpenClContext::listDevices().empty()) GTEST_SKIP() << "no OpenCL device";
  TsdfConfig cpu_cfg, cl_cfg;
  cl_cfg.integrator = TsdfIntegratorKind::kOpenCl;
  TsdfMap cpu(cpu_cfg), cl(cl_cfg);
  const CameraModel cam = smallFisheye();
  const Scene scene = objectsScene();
  const auto poses = orbit();
  for (size_t i = 0; i < poses.size(); i += 3) {
    const cv::Mat depth = scene.render(cam, poses[i]);
    const Eigen::Vector3d vehicle(poses[i].translation().x(), poses[i].translation().y(), 0);
    cpu.integrate(depth, cam, poses[i], vehicle);
    cl.integrate(depth, cam, poses[i], vehicle);
  }
  ASSERT_EQ(cpu.numBlocks(), cl.numBlocks());
  ASSERT_GT(cpu.numBlocks(), 500u);
  // Float rounding differs between compilers (OpenCL contracts a * b + c into
  // FMAs): a voxel right at a pixel's border or at eta = -mu may go either way.
  double worst = 0;
  size_t observed = 0, weight_differs = 0, tsdf_differs = 0;
  for (const BlockIndex& b : cpu.allBlocks()) {
    const VoxelBlock* a = cpu.block(b);
    const VoxelBlock* c = cl.block(b);
    ASSERT_NE(c, nullptr);
    for (int v = 0; v < FM_BLOCK_VOXELS; ++v) {
      if (a->voxels[v].weight != c->voxels[v].weight) {
        ++weight_differs;
        continue;
      }
      const double diff = std::abs(a->voxels[v].tsdf - c->voxels[v].tsdf);
      worst = std::max(worst, diff);
      tsdf_differs += diff > 1e-4;
      observed += a->voxels[v].weight > 0;
    }
  }
  std::cout << observed << " observed voxels, " << weight_differs << " with another weight, " << tsdf_differs
            << " with a tsdf differing by more than 1e-4 (worst " << worst << ")\n";
  EXPECT_GT(observed, 100000u);
  EXPECT_LE(weight_differs, observed / 1000);
  EXPECT_LE(tsdf_differs, observed / 1000);
  EXPECT_EQ(cpu.takeChangedBlocks().size(), cl.takeChangedBlocks().size());
}

TEST(TsdfMap, BadInputIsRejectedAndTheMapKept) {
  TsdfMap map;
  const CameraModel cam = smallFisheye();
  const Scene s = street();
  map.integrate(s.render(cam, carCamera(0)), cam, carCamera(0), Eigen::Vector3d::Zero());
  const auto before = snapshot(map);
  cv::Mat wrong_type(cam.height(), cam.width(), CV_16UC1, cv::Scalar(1000));
  cv::Mat wrong_size(100, 100, CV_32FC1, cv::Scalar(5.0f));
  EXPECT_THROW(map.integrate(wrong_type, cam, carCamera(0), Eigen::Vector3d::Zero()), std::invalid_argument);
  EXPECT_THROW(map.integrate(wrong_size, cam, carCamera(0), Eigen::Vector3d::Zero()), std::invalid_argument);
  Eigen::Isometry3d bad = carCamera(0);
  bad.translation().x() = NAN;
  EXPECT_THROW(map.integrate(s.render(cam, carCamera(0)), cam, bad, Eigen::Vector3d::Zero()),
               std::invalid_argument);
  // inf and negative depths are no measurement.
  cv::Mat junk(cam.height(), cam.width(), CV_32FC1, cv::Scalar(INFINITY));
  junk.colRange(0, 50).setTo(-3.0f);
  const IntegrationStats st = map.integrate(junk, cam, carCamera(0), Eigen::Vector3d::Zero());
  EXPECT_EQ(st.valid_pixels, 0u);
  expectSameBlocks(map, before);
  TsdfConfig cfg;
  cfg.voxel_size = -1;
  EXPECT_THROW({ TsdfMap m(cfg); }, std::invalid_argument);
}

}  // namespace
}  // namespace fisheye_mapping
