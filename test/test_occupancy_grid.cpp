// The planner's obstacle grid (core/tsdf/occupancy_grid.h) against ground
// truth: the synthetic city's own geometry (World::occupancyAt: the static
// scene and its parked vehicles) for a map fused from rendered depth; an
// analytic slope for the ground that is not z = 0; hand-made maps for the
// bad inputs.
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>

#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/sim/analytic_scene.h"
#include "fisheye_mapping/core/sim/synthetic_world.h"
#include "fisheye_mapping/core/tsdf/occupancy_grid.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"
#include "test_utils.h"

namespace fm = fisheye_mapping;

namespace {

const std::string kData = FM_TEST_DATA_DIR;

fm::TsdfConfig mapConfig() {
  fm::TsdfConfig c;
  c.voxel_size = 0.1;
  c.local_map_size = Eigen::Vector3d(80, 80, 12);
  c.local_map_offset = Eigen::Vector3d(0, 0, 3);
  return c;
}

TEST(OccupancyGrid, CityDriveMatchesTheWorldsObstaclesAndRoad) {
  fm::synth::WorldConfig wc;
  wc.preset = "urban";
  wc.seed = 5;
  wc.moving_vehicles = 0;
  const fm::synth::World world(wc);
  const fm::Rig rig = fm::loadKalibrRig(kData + "/small_rig_camchain.yaml", kData + "/small_rig_mount.yaml");
  fm::TsdfMap map(mapConfig());
  std::vector<std::vector<Eigen::Vector3f>> rays;
  for (const auto& cam : rig.cameras) rays.push_back(fm::pixelRays(cam.model));
  std::vector<Eigen::Vector2d> path;
  const double t_end = 6.0;
  for (double t = 0; t <= t_end + 1e-9; t += 0.25) {
    const Eigen::Isometry3d T_W_B = world.egoPose(t);
    path.push_back(T_W_B.translation().head<2>());
    for (size_t c = 0; c < rig.cameras.size(); ++c) {
      const Eigen::Isometry3d T_W_C = T_W_B * rig.cameras[c].T_base_cam;
      const auto frame = world.render(rig.cameras[c].model, rays[c], T_W_C, t, 3);
      map.integrate(frame.depth, rig.cameras[c].model, T_W_C, T_W_B.translation());
    }
  }
  fm::OccupancyGridConfig gc;  // the defaults: 40 x 40 m at 0.2 m, obstacles 0.3..2 m
  const fm::OccupancyGrid grid = fm::computeOccupancyGrid(map, world.egoPose(t_end / 2).translation(), gc, 3);
  ASSERT_EQ(grid.width, 200);
  ASSERT_EQ(grid.height, 200);
  // The distance field comes with it (the default 5 m cap): 0 on obstacles.
  ASSERT_EQ(grid.distance.size(), grid.cells.size());
  for (size_t i = 0; i < grid.cells.size(); ++i) {
    if (grid.cells[i] == fm::OccupancyGrid::kOccupied) {
      ASSERT_EQ(grid.distance[i], 0.0f);
    } else if (grid.cells[i] == fm::OccupancyGrid::kFree) {
      ASSERT_GT(grid.distance[i], 0.0f);
    }
  }
  // The ground the grid found is the world's (z = 0) where it found one.
  size_t with_ground = 0, off = 0;
  for (float z : grid.ground) {
    if (!(z == z)) continue;
    ++with_ground;
    off += std::abs(z) > 0.1f;
  }
  ASSERT_GT(with_ground, 1000u);
  EXPECT_LT(off, with_ground / 50) << "local ground more than 0.1 m off z = 0";
  // Scored within 10 m of the stretch driven (what the cameras saw closely).
  auto near_path = [&](double x, double y) {
    for (const auto& p : path) {
      if ((p - Eigen::Vector2d(x, y)).norm() < 10.0) return true;
    }
    return false;
  };
  const fm::OccupancyScore s = fm::scoreOccupancy(
      grid, [&](double x, double y) { return world.occupancyAt(x, y, gc.obstacle_height, gc.vehicle_height); }, 1,
      near_path);
  std::printf("occupied: precision %.3f (%zu cells), recall %.3f (%zu boundary cells); free: precision %.3f (%zu), "
              "recall %.3f (%zu)\n",
              s.occupiedPrecision(), s.map_occupied, s.occupiedRecall(), s.true_boundary, s.freePrecision(),
              s.map_free, s.freeRecall(), s.true_free);
  ASSERT_GT(s.map_occupied, 100u);
  ASSERT_GT(s.map_free, 1000u);
  EXPECT_GE(s.occupiedPrecision(), 0.9);
  EXPECT_GE(s.occupiedRecall(), 0.8);
  EXPECT_GE(s.freePrecision(), 0.95);
}

// The ground of a 6 degree slope (10.5 %), not z = 0: its cells are free, a
// 1 m box on it is an obstacle, and a canopy 3 m above the slope is not.
TEST(OccupancyGrid, FollowsASlopeAndIgnoresOverhangs) {
  fm::analytic::Scene scene;
  scene.boxes.push_back({Eigen::Vector3d(8, -1, 0), Eigen::Vector3d(9, 1, 1.0)});      // obstacle
  scene.boxes.push_back({Eigen::Vector3d(4, 2, 3.0), Eigen::Vector3d(7, 5, 3.3)});     // canopy
  scene.min_incidence_cos = 0.05;
  const fm::CameraModel cam = fm::CameraModel::unified(fm::test::makeIntrinsics(130, 130, 127.5, 67.5, 256, 136), 0.98,
                                                       -0.02, 0.004, 2e-4, -1e-4);
  // The scene tilted about the y axis: world = R * scene.
  const double tilt = 6.0 * M_PI / 180.0;
  const Eigen::Isometry3d R(Eigen::AngleAxisd(-tilt, Eigen::Vector3d::UnitY()));
  fm::TsdfMap map(mapConfig());
  for (double x = -6; x <= 4; x += 1.0) {
    for (double yaw : {-0.6, 0.0, 0.6}) {
      const Eigen::Isometry3d T_S_C = fm::analytic::lookAt(
          Eigen::Vector3d(x, 0, 1.6), Eigen::Vector3d(x + 10 * std::cos(yaw), 10 * std::sin(yaw), 0));
      const Eigen::Isometry3d T_W_C = R * T_S_C;
      map.integrate(scene.render(cam, T_S_C), cam, T_W_C, T_W_C.translation());
    }
  }
  fm::OccupancyGridConfig gc;
  gc.size = 20;
  const fm::OccupancyGrid grid = fm::computeOccupancyGrid(map, Eigen::Vector3d(5, 0, 0), gc, 3);
  // World (x, y) of a scene point on the ground (z_scene = 0).
  auto world_xy = [&](double xs, double ys) -> Eigen::Vector2d { return (R * Eigen::Vector3d(xs, ys, 0)).head<2>(); };
  auto cell = [&](double xs, double ys) {
    int cx, cy;
    const Eigen::Vector2d p = world_xy(xs, ys);
    return grid.cellOf(p.x(), p.y(), &cx, &cy) ? grid.at(cx, cy) : int8_t(-2);
  };
  // The slope rises 0.5 m from x = 0 to x = 5 (scene): a z = 0 ground would call it an obstacle.
  EXPECT_GT((R * Eigen::Vector3d(9, 0, 0)).z(), 0.9);
  size_t ground = 0, ground_free = 0, ground_occupied = 0;
  for (double xs = 1; xs <= 14; xs += 0.5) {
    for (double ys = -4; ys <= 4; ys += 0.5) {
      if (xs > 7.5 && xs < 9.5 && std::abs(ys) < 1.5) continue;  // the box and its edges
      if (xs > 3.5 && xs < 7.5 && ys > 1.5) continue;             // under the canopy: below
      const int8_t v = cell(xs, ys);
      if (v == -2 || v == -1) continue;
      ++ground;
      ground_free += v == 0;
      ground_occupied += v == 100;
    }
  }
  ASSERT_GT(ground, 100u);
  EXPECT_GT(ground_free, ground * 95 / 100) << ground_occupied << " of " << ground << " slope cells occupied";
  // The box: occupied.
  size_t box = 0, box_occupied = 0;
  for (double xs = 8.05; xs < 9.0; xs += 0.2)
    for (double ys = -0.95; ys < 1.0; ys += 0.2) {
      ++box;
      box_occupied += cell(xs, ys) == 100;
    }
  EXPECT_GT(box_occupied, box / 2) << box_occupied << " of " << box << " box cells occupied";
  // Under the canopy (3 m over the slope, above vehicle_height): not occupied.
  size_t canopy = 0, canopy_occupied = 0;
  for (double xs = 4.3; xs < 6.8; xs += 0.2)
    for (double ys = 2.3; ys < 4.8; ys += 0.2) {
      const int8_t v = cell(xs, ys);
      if (v < 0) continue;
      ++canopy;
      canopy_occupied += v == 100;
    }
  EXPECT_EQ(canopy_occupied, 0u) << "of " << canopy << " cells seen under the canopy";
}

// Nothing but a wall (no ground seen yet): every cell unknown, none free.
TEST(OccupancyGrid, NoGroundYetIsAllUnknown) {
  fm::TsdfMap empty(mapConfig());
  fm::OccupancyGridConfig gc;
  fm::OccupancyGrid g = fm::computeOccupancyGrid(empty, Eigen::Vector3d::Zero(), gc, 3);
  EXPECT_EQ(g.unknown, g.cells.size());
  fm::analytic::Scene wall;
  wall.ground = false;
  wall.boxes.push_back({Eigen::Vector3d(6, -5, 0), Eigen::Vector3d(7, 5, 3)});
  const fm::CameraModel cam = fm::CameraModel::unified(fm::test::makeIntrinsics(130, 130, 127.5, 67.5, 256, 136), 0.98,
                                                       -0.02, 0.004, 2e-4, -1e-4);
  fm::TsdfMap map(mapConfig());
  for (int i = 0; i < 4; ++i) {
    const Eigen::Isometry3d T = fm::analytic::lookAt(Eigen::Vector3d(0, 0.2 * i, 1.5), Eigen::Vector3d(10, 0, 1.5));
    map.integrate(wall.render(cam, T), cam, T, T.translation());
  }
  ASSERT_GT(map.numBlocks(), 0u);
  g = fm::computeOccupancyGrid(map, Eigen::Vector3d::Zero(), gc, 3);
  EXPECT_EQ(g.free, 0u);
  EXPECT_EQ(g.occupied, 0u);
  EXPECT_EQ(g.unknown, g.cells.size());
}

TEST(OccupancyGrid, BadParametersAreNamedAndRefused) {
  fm::TsdfMap map(mapConfig());
  auto refused = [&](fm::OccupancyGridConfig c, const std::string& name) {
    try {
      fm::computeOccupancyGrid(map, Eigen::Vector3d::Zero(), c, 3);
      ADD_FAILURE() << name << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  };
  fm::OccupancyGridConfig c;
  c.size = 0;
  refused(c, "occupancy_size");
  c = fm::OccupancyGridConfig();
  c.size = -5;
  refused(c, "occupancy_size");
  c = fm::OccupancyGridConfig();
  c.resolution = 0;
  refused(c, "occupancy_resolution");
  c = fm::OccupancyGridConfig();
  c.resolution = -0.2;
  refused(c, "occupancy_resolution");
  c = fm::OccupancyGridConfig();
  c.size = 900;
  c.resolution = 0.01;  // 90000 cells a side
  refused(c, "occupancy_size / occupancy_resolution");
  c = fm::OccupancyGridConfig();
  c.size = NAN;
  refused(c, "occupancy_size");
  c = fm::OccupancyGridConfig();
  c.vehicle_height = 0.2;
  refused(c, "occupancy_vehicle_height");
  c = fm::OccupancyGridConfig();
  c.esdf_max_distance = -1;
  refused(c, "esdf_max_distance");
  c.esdf_max_distance = NAN;
  refused(c, "esdf_max_distance");
}

TEST(OccupancyGrid, ScoresCountByHand) {
  // A 3 x 1 grid: occupied, free, unknown; the truth: occupied, free, free.
  fm::OccupancyGrid g;
  g.resolution = 1.0;
  g.width = 3, g.height = 1;
  g.cells = {100, 0, -1};
  auto truth = [](double x, double) -> int8_t { return x < 1 ? 100 : 0; };
  const fm::OccupancyScore s = fm::scoreOccupancy(g, truth, 0);
  EXPECT_EQ(s.map_occupied, 1u);
  EXPECT_EQ(s.occupied_right, 1u);
  EXPECT_EQ(s.true_boundary, 1u);  // the occupied cell next to a free one
  EXPECT_EQ(s.boundary_found, 1u);
  EXPECT_EQ(s.map_free, 1u);
  EXPECT_EQ(s.free_right, 1u);
  EXPECT_EQ(s.true_free, 2u);
  EXPECT_EQ(s.free_found, 1u);
  EXPECT_DOUBLE_EQ(s.freeRecall(), 0.5);
}

}  // namespace

namespace {

// The recall of what a camera could see, by hand: a 2 m thick wall (cells
// x = 4, 5) across a 10 x 3 grid of 1 m cells, a viewpoint at x = 0.5 facing
// it. Its near face (x = 4) is visible, its far face (x = 5) is not.
TEST(OccupancyGrid, VisibleRecallCountsOnlyWhatTheCamerasCouldSee) {
  fm::OccupancyGrid g;
  g.resolution = 1.0;
  g.width = 10, g.height = 3;
  g.cells.assign(30, fm::OccupancyGrid::kUnknown);
  g.cells[1 * 10 + 4] = fm::OccupancyGrid::kOccupied;  // the map found one near-face cell
  g.cells[1 * 10 + 5] = fm::OccupancyGrid::kOccupied;  // and one of the far face
  auto truth = [](double x, double) -> int8_t { return x > 4 && x < 6 ? 100 : 0; };
  fm::OccupancyViewpoints views;
  views.position = {Eigen::Vector2d(0.5, 1.5)};
  views.heading = {Eigen::Vector2d(1, 0)};
  std::vector<uint8_t> label;
  fm::OccupancyScore s = fm::scoreOccupancy(g, truth, 0, nullptr, &views, &label);
  EXPECT_EQ(s.true_boundary, 6u);  // both faces, three rows
  EXPECT_EQ(s.boundary_found, 2u);
  EXPECT_EQ(s.visible_boundary, 3u);  // the near face only
  EXPECT_EQ(s.visible_found, 1u);
  EXPECT_DOUBLE_EQ(s.visibleRecall(), 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(s.occupiedRecall(), 2.0 / 6.0);
  ASSERT_EQ(label.size(), 30u);
  EXPECT_EQ(label[1 * 10 + 4], fm::OccupancyScore::kBoundaryFound);
  EXPECT_EQ(label[0 * 10 + 4], fm::OccupancyScore::kBoundaryMissed);
  EXPECT_EQ(label[1 * 10 + 5], fm::OccupancyScore::kBoundaryFound);  // found, though hidden
  EXPECT_EQ(label[0 * 10 + 5], fm::OccupancyScore::kBoundaryHidden);
  EXPECT_EQ(label[1 * 10 + 2], 0);  // free
  // Facing away, or out of range: nothing was visible.
  views.heading = {Eigen::Vector2d(-1, 0)};
  EXPECT_EQ(fm::scoreOccupancy(g, truth, 0, nullptr, &views).visible_boundary, 0u);
  views.heading = {Eigen::Vector2d(1, 0)};
  views.range = 3.0;
  EXPECT_EQ(fm::scoreOccupancy(g, truth, 0, nullptr, &views).visible_boundary, 0u);
  // A viewpoint on each side sees both faces.
  views.range = 20.0;
  views.position.push_back(Eigen::Vector2d(9.5, 1.5));
  views.heading.push_back(Eigen::Vector2d(-1, 0));
  s = fm::scoreOccupancy(g, truth, 0, nullptr, &views);
  EXPECT_EQ(s.visible_boundary, 6u);
  EXPECT_EQ(s.visible_found, 2u);
}

}  // namespace

namespace {

// The distance field by hand: one obstacle cell in a 20 x 20 grid of 0.2 m
// cells, one unknown cell; distances are Euclidean between cell centres.
TEST(OccupancyGrid, DistanceFieldIsTheDistanceToTheNearestObstacle) {
  fm::OccupancyGrid g;
  g.resolution = 0.2;
  g.width = g.height = 20;
  g.cells.assign(400, fm::OccupancyGrid::kFree);
  g.cells[5 * 20 + 5] = fm::OccupancyGrid::kOccupied;
  g.cells[0 * 20 + 19] = fm::OccupancyGrid::kUnknown;
  fm::computeDistanceField(&g, 1.5);
  ASSERT_EQ(g.distance.size(), 400u);
  auto d = [&](int x, int y) { return g.distance[static_cast<size_t>(y) * 20 + x]; };
  EXPECT_FLOAT_EQ(d(5, 5), 0.0f);
  EXPECT_NEAR(d(6, 5), 0.2f, 1e-5);
  EXPECT_NEAR(d(8, 9), 1.0f, 1e-5);                    // 3-4-5 cells
  EXPECT_NEAR(d(7, 7), 0.2f * std::sqrt(8.0f), 1e-5);  // the diagonal, exact
  EXPECT_FLOAT_EQ(d(19, 19), 1.5f);                    // 3.96 m away: the cap
  EXPECT_TRUE(std::isnan(d(19, 0)));                   // unknown: no claim
  // A second obstacle takes over where it is nearer.
  g.cells[5 * 20 + 10] = fm::OccupancyGrid::kOccupied;
  fm::computeDistanceField(&g, 1.5);
  EXPECT_NEAR(d(9, 5), 0.2f, 1e-5);
  EXPECT_NEAR(d(7, 5), 0.4f, 1e-5);
  // No obstacle at all: the cap everywhere known; a zero cap: no field.
  g.cells.assign(400, fm::OccupancyGrid::kFree);
  fm::computeDistanceField(&g, 2.0);
  EXPECT_FLOAT_EQ(d(3, 3), 2.0f);
  fm::computeDistanceField(&g, 0.0);
  EXPECT_TRUE(g.distance.empty());
}

}  // namespace
