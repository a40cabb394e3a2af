// The TSDF stage without ROS (TsdfFusionStage, what the Tsdf nodelet
// runs) and the order-keeping wait of its depth frames (OrderedWait): checked
// against hand-made sequences, an analytic wall and the files on disk.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include "fisheye_mapping/core/common/ordered_wait.h"
#include "fisheye_mapping/core/sim/analytic_scene.h"
#include "fisheye_mapping/core/tsdf/fusion_stage.h"
#include "test_utils.h"

namespace fisheye_mapping {
namespace {

namespace fs = std::filesystem;
constexpr std::int64_t kS = 1000000000;  // ns per s

// ---------------------------------------------------------------- OrderedWait
TEST(OrderedWait, KeepsTheOrderTheItemsCameIn) {
  std::set<std::string> known;
  auto is_known = [&](const std::string& k) { return known.count(k) > 0; };
  OrderedWait<int> w(3, 2.0);
  known.insert("a");
  EXPECT_EQ(w.arrive(1, "a", 0.0, is_known), std::vector<int>({1}));  // nothing waits: goes on
  EXPECT_TRUE(w.arrive(2, "b", 0.1, is_known).empty());               // b unknown: waits
  EXPECT_TRUE(w.arrive(3, "a", 0.2, is_known).empty());               // behind 2: waits though a is known
  EXPECT_EQ(w.size(), 2u);
  known.insert("b");
  EXPECT_EQ(w.release(is_known), std::vector<int>({2, 3}));
  EXPECT_EQ(w.size(), 0u);
}

TEST(OrderedWait, TheOldestBeyondTheLimitAndTheExpiredGoOnUnknown) {
  std::set<std::string> known;
  auto is_known = [&](const std::string& k) { return known.count(k) > 0; };
  OrderedWait<int> w(2, 2.0);
  EXPECT_TRUE(w.arrive(1, "b", 0.0, is_known).empty());
  EXPECT_TRUE(w.arrive(2, "b", 1.0, is_known).empty());
  EXPECT_EQ(w.arrive(3, "b", 1.5, is_known), std::vector<int>({1}));  // three waiting, two allowed
  EXPECT_TRUE(w.expire(2.9, is_known).empty());                       // 2 came at 1.0: waited 1.9 s
  EXPECT_EQ(w.expire(3.1, is_known), std::vector<int>({2}));          // 2.1 s
  known.insert("b");
  EXPECT_EQ(w.expire(3.2, is_known), std::vector<int>({3}));  // not expired, but its key has come
}

// ------------------------------------------------------------- TsdfFusionStage
TsdfConfig smallMap() {
  TsdfConfig cfg;
  cfg.voxel_size = 0.1;
  cfg.local_map_size = Eigen::Vector3d(20, 20, 3);
  cfg.min_observations = 1;
  return cfg;
}

struct Wall {
  CameraModel cam = CameraModel::unified(test::makeIntrinsics(130, 130, 127.5, 67.5, 256, 136), 0.98, 0, 0, 0, 0);
  analytic::Scene scene;
  Wall() { scene.boxes.push_back({Eigen::Vector3d(6, -10, 0), Eigen::Vector3d(7, 10, 4)}); }
  // The camera 1.5 m up, looking at the wall; the vehicle below it.
  Eigen::Isometry3d camera(int i) const {
    return analytic::lookAt(Eigen::Vector3d(0.1 * i, 0, 1.5), Eigen::Vector3d(10, 0, 1.5));
  }
  Eigen::Isometry3d base(int i) const {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation() = Eigen::Vector3d(0.1 * i, 0, 0.3);
    return T;
  }
  TsdfFusionStage::Fused fuse(TsdfFusionStage& s, int i, std::int64_t stamp) const {
    return s.fuse(scene.render(cam, camera(i)), cam, camera(i), base(i), stamp);
  }
};

TsdfFusionStage::Log quiet() {
  return [](bool, const std::string&) {};
}

TEST(TsdfFusionStage, TimeGoingBackIsAResetOrOutOfOrder) {
  Wall wall;
  TsdfStageOptions opts;
  opts.time_reset_threshold = 1.0;
  opts.clear_map_on_time_reset = true;
  TsdfFusionStage s(smallMap(), opts, quiet());
  EXPECT_EQ(s.admit(10 * kS).verdict, TsdfFusionStage::Verdict::kFuse);
  wall.fuse(s, 0, 10 * kS);
  EXPECT_EQ(s.admit(11 * kS).verdict, TsdfFusionStage::Verdict::kFuse);
  wall.fuse(s, 1, 11 * kS);
  EXPECT_EQ(s.lastStamp(), 11 * kS);
  EXPECT_GT(s.map().numBlocks(), 0u);
  s.updateMesh();
  EXPECT_FALSE(s.takeMeshReset());
  // 0.5 s back: within the threshold, out of order.
  EXPECT_EQ(s.admit(10 * kS + kS / 2).verdict, TsdfFusionStage::Verdict::kOutOfOrder);
  // 6 s back: a time reset; clear_map_on_time_reset empties the map and the mesh.
  const TsdfFusionStage::Admission a = s.admit(5 * kS);
  EXPECT_EQ(a.verdict, TsdfFusionStage::Verdict::kTimeReset);
  EXPECT_FALSE(a.reason.empty());
  EXPECT_EQ(s.map().numBlocks(), 0u);
  EXPECT_EQ(s.lastStamp(), 0);
  EXPECT_TRUE(s.takeMeshReset());
  EXPECT_FALSE(s.takeMeshReset());  // once
  EXPECT_TRUE(s.mesher().blocks().empty());
  // The new time line goes on from there.
  EXPECT_EQ(s.admit(5 * kS + kS / 10).verdict, TsdfFusionStage::Verdict::kFuse);
}

TEST(TsdfFusionStage, ATimeResetKeepsTheMapUnlessAsked) {
  Wall wall;
  TsdfFusionStage s(smallMap(), TsdfStageOptions(), quiet());
  ASSERT_EQ(s.admit(10 * kS).verdict, TsdfFusionStage::Verdict::kFuse);  // what the nodelet does before fuse()
  wall.fuse(s, 0, 10 * kS);
  const size_t blocks = s.map().numBlocks();
  std::string reason;
  EXPECT_TRUE(s.checkTimeReset(2 * kS, &reason));
  EXPECT_EQ(s.map().numBlocks(), blocks);
  EXPECT_FALSE(s.takeMeshReset());
}

// observation_travel: a frame counts in proportion to its camera's travel
// (or turn) since the previous frame, by hand; a camera standing still before
// the wall adds (almost) no observations, so the wall stays out of the cloud
// until the camera has moved, whatever the frame rate.
TEST(TsdfFusionStage, FramesCountByTheCamerasTravel) {
  Wall wall;
  TsdfConfig cfg = smallMap();
  cfg.min_observations = 3;
  cfg.observation_travel = 2.0;
  cfg.observation_turn = 10.0;
  TsdfFusionStage s(cfg, TsdfStageOptions(), quiet());
  // wall.camera(i) stands 0.1 i m along x.
  EXPECT_FLOAT_EQ(s.observationWeight(wall.camera(0)), 1.0f) << "no previous frame";
  EXPECT_FLOAT_EQ(wall.fuse(s, 0, 1 * kS).observation_weight, 1.0f);
  EXPECT_FLOAT_EQ(s.observationWeight(wall.camera(10)), 0.5f) << "1 m of 2";
  EXPECT_FLOAT_EQ(s.observationWeight(wall.camera(30)), 1.0f) << "3 m: capped at 1";
  EXPECT_FLOAT_EQ(s.observationWeight(wall.camera(0)), kMinObservationWeight) << "standing still";
  Eigen::Isometry3d turned = wall.camera(0);
  turned.linear() = turned.linear() * Eigen::AngleAxisd(4.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  EXPECT_NEAR(s.observationWeight(turned), 0.4f, 1e-5) << "4 degrees of 10";
  // Standing still: 1 + 19 x 0.01 observations, below min_observations 3.
  for (int k = 1; k < 20; ++k) EXPECT_FLOAT_EQ(wall.fuse(s, 0, (1 + k) * kS).observation_weight, kMinObservationWeight);
  const FmVoxel* v = s.map().voxel(Eigen::Vector3i(59, 0, 15));  // a voxel in front of the wall at x = 6 m
  ASSERT_NE(v, nullptr);
  EXPECT_NEAR(v->weight, 1.19f, 1e-4);
  s.updateMesh();
  EXPECT_EQ(s.mesher().surfaceCloud().size(), 0u) << "no surface from a camera standing still";
  // Moving on 1 m a frame (0.5 each): four frames reach 1.19 + 2 = 3.19 >= 3.
  for (int k = 1; k <= 4; ++k) EXPECT_FLOAT_EQ(wall.fuse(s, 10 * k, (30 + k) * kS).observation_weight, 0.5f);
  s.updateMesh();
  EXPECT_GT(s.mesher().surfaceCloud().size(), 1000u) << "the wall, once the camera has moved";
  // Without observation_travel every frame counts 1: 3 frames from one place are enough.
  TsdfConfig every = smallMap();
  every.min_observations = 3;
  TsdfFusionStage e(every, TsdfStageOptions(), quiet());
  for (int k = 0; k < 3; ++k) EXPECT_FLOAT_EQ(wall.fuse(e, 0, (1 + k) * kS).observation_weight, 1.0f);
  e.updateMesh();
  EXPECT_GT(e.mesher().surfaceCloud().size(), 1000u);
}

TEST(TsdfFusionStage, TheGreyImageOfTheStampColoursTheWall) {
  Wall wall;
  TsdfFusionStage s(smallMap(), TsdfStageOptions(), quiet());
  // A grey image 2 ms off the depth's stamp is not its image.
  s.addGrey(10 * kS + 2000000, cv::Mat(136, 256, CV_8UC1, cv::Scalar(90)));
  EXPECT_FALSE(wall.fuse(s, 0, 10 * kS).with_intensity);
  s.addGrey(11 * kS + 500000, cv::Mat(136, 256, CV_8UC1, cv::Scalar(200)));  // 0.5 ms off: its image
  EXPECT_TRUE(wall.fuse(s, 0, 11 * kS).with_intensity);
  // The wall's face (x = 6 m) straight ahead of the camera: the voxel just in
  // front of it has the grey of the one image fused with it.
  const Eigen::Vector3i v(59, 0, 15);  // centre (5.95, 0.05, 1.55)
  EXPECT_EQ(s.map().grey(v), 200);
  // A grey image of the wrong size: fused without, and said why.
  s.addGrey(12 * kS, cv::Mat(68, 128, CV_8UC1, cv::Scalar(50)));
  const TsdfFusionStage::Fused f = wall.fuse(s, 0, 12 * kS);
  EXPECT_FALSE(f.with_intensity);
  EXPECT_NE(f.intensity_note.find("128x68"), std::string::npos) << f.intensity_note;
  EXPECT_EQ(s.map().grey(v), 200);
}

// Held depth (a vehicle masked while undecided, decided parked later): the
// left half of frame 0 fused at once and the right half held, then fused
// with frame 0's pose, weight and grey after frame 1, gives the map that
// fusing frame 0 whole gives (the update is a weighted running mean, so
// the order of two measurements of one voxel does not matter), and leaves
// the time state as frame 1 left it. A stamp no fused frame had is refused.
TEST(TsdfFusionStage, HeldDepthFusedLateIsFusedWithItsFramesPose) {
  Wall wall;
  TsdfConfig cfg = smallMap();
  cfg.observation_travel = 2.0;
  cfg.observation_turn = 10.0;
  const cv::Mat grey(136, 256, CV_8UC1, cv::Scalar(120));
  TsdfFusionStage whole(cfg, TsdfStageOptions(), quiet()), split(cfg, TsdfStageOptions(), quiet());
  const cv::Mat d0 = wall.scene.render(wall.cam, wall.camera(0));
  const cv::Mat d1 = wall.scene.render(wall.cam, wall.camera(10));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  cv::Mat left = d0.clone(), right(d0.size(), CV_32FC1, cv::Scalar(nan));
  left.colRange(128, 256).copyTo(right.colRange(128, 256));
  left.colRange(128, 256).setTo(nan);
  for (TsdfFusionStage* s : {&whole, &split}) s->addGrey(1 * kS, grey);
  whole.fuse(d0, wall.cam, wall.camera(0), wall.base(0), 1 * kS);
  whole.fuse(d1, wall.cam, wall.camera(10), wall.base(10), 2 * kS);
  split.fuse(left, wall.cam, wall.camera(0), wall.base(0), 1 * kS);
  const float w1 = split.fuse(d1, wall.cam, wall.camera(10), wall.base(10), 2 * kS).observation_weight;
  EXPECT_FLOAT_EQ(w1, 0.5f);  // 1 m of 2
  const auto held = split.fuseHeld(right, wall.cam, 1 * kS);
  ASSERT_TRUE(held);
  EXPECT_FLOAT_EQ(held->observation_weight, 1.0f) << "frame 0's weight, not one from frame 1's pose";
  EXPECT_TRUE(held->with_intensity);
  EXPECT_EQ(split.lastStamp(), 2 * kS);
  EXPECT_EQ(split.framesFused(), 2u);
  EXPECT_EQ(split.heldFramesFused(), 1u);
  EXPECT_FLOAT_EQ(split.observationWeight(wall.camera(10)), kMinObservationWeight) << "still measured from frame 1";
  ASSERT_EQ(split.map().numBlocks(), whole.map().numBlocks());
  size_t compared = 0;
  for (int y = -40; y <= 40; ++y) {
    for (int z = 0; z <= 30; z += 3) {
      const Eigen::Vector3i v(59, y, z);  // just in front of the wall's face
      const FmVoxel* a = whole.map().voxel(v);
      const FmVoxel* b = split.map().voxel(v);
      ASSERT_EQ(a == nullptr, b == nullptr);
      if (!a || a->weight <= 0) continue;
      EXPECT_NEAR(a->tsdf, b->tsdf, 1e-4);
      EXPECT_NEAR(a->weight, b->weight, 1e-4);
      EXPECT_EQ(whole.map().grey(v), split.map().grey(v));
      ++compared;
    }
  }
  EXPECT_GT(compared, 200u);
  // No fused frame of that stamp: nothing fused.
  const size_t blocks = split.map().numBlocks();
  EXPECT_FALSE(split.fuseHeld(d0, wall.cam, 3 * kS));
  EXPECT_EQ(split.heldFramesFused(), 1u);
  EXPECT_EQ(split.map().numBlocks(), blocks);
}

// The map's own memory on the report: its blocks (4608 bytes each: 512 voxels
// of 8 bytes and 512 grey bytes) and its mesh's vertices, once meshed.
TEST(TsdfFusionStage, TheReportCountsTheMapsOwnMemory) {
  Wall wall;
  TsdfFusionStage s(smallMap(), TsdfStageOptions(), quiet());
  for (int i = 0; i < 3; ++i) wall.fuse(s, i, (10 + i) * kS);
  auto value = [&s](const std::string& key) {
    std::vector<std::string> warnings;
    for (const auto& [k, v] : s.report(&warnings))
      if (k == key) return v;
    return std::string("missing");
  };
  ASSERT_EQ(sizeof(VoxelBlock), 4608u);
  const size_t blocks = s.map().numBlocks();
  ASSERT_GT(blocks, 100u);
  EXPECT_NEAR(std::stod(value("voxel memory (MB)")), blocks * 4608.0 / 1048576.0, 0.051);
  EXPECT_EQ(value("mesh triangles"), "0");  // not meshed yet
  EXPECT_EQ(value("mesh memory (MB)"), "0");
  s.updateMesh();
  const double triangles = std::stod(value("mesh triangles"));
  ASSERT_GT(triangles, 1000);
  // At least 3 vertices of 12 bytes and 3 grey bytes per triangle.
  EXPECT_GE(std::stod(value("mesh memory (MB)")), triangles * 39.0 / 1048576.0 - 0.051);
}

TEST(TsdfFusionStage, TheObstacleGridLiesAroundTheLastVehiclePose) {
  Wall wall;
  TsdfStageOptions opts;
  opts.occupancy.size = 20.0;
  opts.occupancy.resolution = 0.5;
  TsdfFusionStage s(smallMap(), opts, quiet());
  double z = -1;
  EXPECT_FALSE(s.occupancy(&z).has_value());  // no pose yet
  wall.fuse(s, 3, 10 * kS);
  const std::optional<OccupancyGrid> grid = s.occupancy(&z);
  ASSERT_TRUE(grid.has_value());
  EXPECT_DOUBLE_EQ(z, 0.3);
  EXPECT_EQ(grid->width, 40);
  EXPECT_EQ(grid->height, 40);
  // Centred on the vehicle at x = 0.3 m, snapped to whole cells.
  EXPECT_NEAR(grid->origin.x() + 10.0, 0.3, 0.5);
  EXPECT_NEAR(grid->origin.y() + 10.0, 0.0, 0.5);
}

TEST(TsdfFusionStage, RunTimeSettingsAreCheckedAndRemesh) {
  Wall wall;
  TsdfFusionStage s(smallMap(), TsdfStageOptions(), quiet());
  for (int i = 0; i < 3; ++i) wall.fuse(s, i, (10 + i) * kS);
  ASSERT_FALSE(s.updateMesh().empty());
  TsdfConfig bad = s.config();
  bad.max_range = -1;
  EXPECT_THROW(s.reconfigure(bad), std::invalid_argument);
  EXPECT_EQ(s.config().max_range, smallMap().max_range);
  TsdfConfig next = s.config();
  next.max_range = 30;
  EXPECT_TRUE(s.reconfigure(next).empty());  // a range applies to later frames: no re-mesh
  EXPECT_EQ(s.map().config().max_range, 30);
  next.min_observations = 100;  // more than any voxel has: the mesh empties
  EXPECT_FALSE(s.reconfigure(next).empty());
  EXPECT_TRUE(s.takeCloudStale());
  EXPECT_EQ(s.mesher().numTriangles(), 0u);
}

// Failed swap writes (the swap folder became a file) are logged by the stage
// through its log, at most once per 5 s, with the count so far; the blocks
// stay in memory.
TEST(TsdfFusionStage, FailedSwapWritesAreLoggedNotEveryTime) {
  const fs::path dir = fs::temp_directory_path() / ("fm_stage_swap_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  TsdfConfig cfg = smallMap();
  cfg.swap_directory = (dir / "swap").string();
  std::vector<std::string> errors;
  TsdfFusionStage s(cfg, TsdfStageOptions(), [&](bool error, const std::string& m) {
    if (error) errors.push_back(m);
  });
  Wall wall;
  for (int i = 0; i < 3; ++i) wall.fuse(s, i, (10 + i) * kS);
  const size_t blocks = s.map().numBlocks();
  ASSERT_GT(blocks, 10u);
  fs::remove_all(dir / "swap");
  std::ofstream(dir / "swap") << "not a folder";
  // The vehicle 500 m away, then back, then away again: the wall's blocks
  // leave the local map twice and cannot be written either time.
  Eigen::Isometry3d far = wall.base(0), far_cam = wall.camera(0);
  far.translation().x() += 500, far_cam.translation().x() += 500;
  const cv::Mat nothing(136, 256, CV_32FC1, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  s.fuse(nothing, wall.cam, far_cam, far, 13 * kS);
  const size_t failed_once = s.map().numSwapWriteFailures();
  EXPECT_EQ(failed_once, s.map().numBlocks());  // every block: none is lost, all stay in memory
  wall.fuse(s, 0, 14 * kS);
  s.fuse(nothing, wall.cam, far_cam, far, 15 * kS);
  EXPECT_GT(s.map().numSwapWriteFailures(), failed_once);
  ASSERT_EQ(errors.size(), 1u) << "one message within 5 s, not one per block";
  EXPECT_NE(errors[0].find(" swap writes failed so far)"), std::string::npos) << errors[0];
  EXPECT_EQ(s.map().numLostBlocks(), 0u);
  fs::remove_all(dir);
}

TEST(TsdfFusionStage, TheMapFileIsSavedOnShutdownAndReloaded) {
  const fs::path dir = fs::temp_directory_path() / ("fm_stage_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  TsdfStageOptions opts;
  opts.map_file = (dir / "map.fmmap").string();
  opts.reload_map_on_start = true;
  Wall wall;
  size_t blocks = 0;
  {
    TsdfFusionStage s(smallMap(), opts, quiet());
    EXPECT_TRUE(s.persistent());
    for (int i = 0; i < 3; ++i) wall.fuse(s, i, (10 + i) * kS);
    blocks = s.map().numBlocks();
    s.shutdown();
  }
  ASSERT_TRUE(fs::exists(opts.map_file));
  TsdfFusionStage again(smallMap(), opts, quiet());
  EXPECT_EQ(again.map().numBlocks(), blocks);
  EXPECT_TRUE(again.takeMeshReset());  // the mesh of the reloaded map is to be made
  again.clear();
  EXPECT_EQ(again.map().numBlocks(), 0u);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace fisheye_mapping
