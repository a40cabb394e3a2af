// occupancy_eval: the planner's obstacle grid (core/tsdf/occupancy_grid.h,
// what the TSDF nodelet publishes on tsdf/occupancy) of a saved map, as a
// picture, and (with the drive's world.yaml from make_drive) scored against
// the synthetic world's ground truth (World::occupancyAt: the static scene and
// its parked vehicles) within --within metres of the ego path.
//
//   occupancy_eval MAP --png OUT.png [--world DRIVE/world.yaml] [--within 20]
//                  [--center X,Y] [--size S] [--resolution R] [--min-observations N]
//
// Without --center and --size the grid covers the whole map (or, with
// --world, the whole drive plus --within). Exit status: 0 done, 1 failure,
// 2 bad arguments.
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "cli.h"
#include "fisheye_mapping/core/depth/depth_image.h"
#include "fisheye_mapping/core/sim/synthetic_world.h"
#include "fisheye_mapping/core/tsdf/occupancy_grid.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"

namespace fm = fisheye_mapping;

namespace {

const char* kUsage =
    "usage: occupancy_eval MAP --png OUT.png [--world DRIVE/world.yaml] [--within M]\n"
    "                      [--center X,Y] [--size S] [--resolution R] [--min-observations N]\n"
    "  MAP     a TSDF map file (the nodelet's save_map / save_map_on_shutdown, offline_mapper's map.fmtsdf)\n"
    "  --png   the grid as a picture: unknown grey, free white, occupied black; with --world the path red and\n"
    "          the true obstacles' boundary cells the recall counts green (found), magenta (missed) or dark violet (hidden from the path)\n"
    "  --world make_drive's world.yaml: scores occupied / free cells against the world's truth\n"
    "  --within M  score cells within M metres of the ego path (default 20)\n"
    "  --center X,Y and --size S: the grid (default: the whole map or drive); --resolution R (default 0.2 m);\n"
    "  --min-observations N (default 3, the nodelet's)\n";

double number(const std::string& what, const std::string& v) {
  try {
    size_t used = 0;
    const double d = std::stod(v, &used);
    if (used == v.size() && std::isfinite(d)) return d;
  } catch (const std::exception&) {
  }
  throw fm::cli::UsageError(what + " needs a number, got '" + v + "'");
}

}  // namespace

int main(int argc, char** argv) {
  std::string map_path, png, world_yaml;
  double within = 20.0, size = 0.0, resolution = 0.2;
  bool have_center = false;
  Eigen::Vector2d center(0, 0);
  int min_obs = fm::TsdfConfig().min_observations;
  const int rc = fm::cli::parseCommandLine("occupancy_eval", kUsage, [&] {
    fm::cli::forEachOption(argc, argv, 1, [&](const std::string& a, const fm::cli::NextValue& next) {
      if (a == "--png") {
        png = next();
      } else if (a == "--world") {
        world_yaml = next();
      } else if (a == "--within") {
        within = number(a, next());
      } else if (a == "--size") {
        size = number(a, next());
      } else if (a == "--resolution") {
        resolution = number(a, next());
      } else if (a == "--min-observations") {
        min_obs = static_cast<int>(number(a, next()));
        if (min_obs < 1) throw fm::cli::UsageError("--min-observations must be >= 1");
      } else if (a == "--center") {
        const std::string v = next();
        const size_t comma = v.find(',');
        if (comma == std::string::npos) throw fm::cli::UsageError("--center needs X,Y, got '" + v + "'");
        center = Eigen::Vector2d(number(a, v.substr(0, comma)), number(a, v.substr(comma + 1)));
        have_center = true;
      } else if (a.size() > 1 && a[0] == '-') {
        return false;
      } else if (map_path.empty()) {
        map_path = a;
      } else {
        throw fm::cli::UsageError("unexpected argument '" + a + "'");
      }
      return true;
    });
    if (map_path.empty()) throw fm::cli::UsageError("no map file");
    if (png.empty()) throw fm::cli::UsageError("--png is required");
  });
  if (rc >= 0) return rc;
  try {
    const fm::MapFileInfo info = fm::TsdfMap::readHeader(map_path);
    fm::TsdfConfig cfg;
    cfg.voxel_size = info.voxel_size;
    cfg.truncation_voxels = info.truncation_voxels;
    if (info.max_weight > 0) cfg.max_weight = info.max_weight;
    fm::TsdfMap map(cfg);  // no local map centre: every block stays in memory
    map.load(map_path);

    std::unique_ptr<fm::synth::World> world;
    fm::OccupancyViewpoints views;  // the ego path, facing forward: the front rig
    const std::vector<Eigen::Vector2d>& path = views.position;
    if (!world_yaml.empty()) {
      const YAML::Node y = YAML::LoadFile(world_yaml);
      fm::synth::WorldConfig wc;
      wc.preset = y["preset"].as<std::string>();
      wc.seed = y["seed"].as<uint32_t>();
      wc.speed = y["speed"].as<double>();
      wc.moving_vehicles = y["moving_vehicles"].as<int>();
      wc.route_length = y["route_length"].as<double>();
      wc.asphalt_grain = y["asphalt_grain"].as<double>();
      wc.clouds = y["clouds"].as<double>();
      const double duration = y["duration"].as<double>();
      world = std::make_unique<fm::synth::World>(wc);
      views.range = within;
      for (double t = 0; t <= duration + 1e-9; t += 0.1) {
        const Eigen::Isometry3d T_W_B = world->egoPose(t);
        views.position.push_back(T_W_B.translation().head<2>());
        views.heading.push_back(T_W_B.linear().col(0).head<2>().normalized());  // base_link x: forward
      }
    }
    // The grid's square: given, or around the path, or around the map.
    if (!have_center || size <= 0) {
      Eigen::Vector2d lo(INFINITY, INFINITY), hi(-INFINITY, -INFINITY);
      if (!path.empty()) {
        for (const auto& p : path) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
        lo -= Eigen::Vector2d::Constant(within), hi += Eigen::Vector2d::Constant(within);
      } else {
        for (const fm::BlockIndex& b : map.allBlocks()) {
          lo = lo.cwiseMin(b.head<2>().cast<double>() * cfg.blockSize());
          hi = hi.cwiseMax((b.head<2>().cast<double>() + Eigen::Vector2d::Ones()) * cfg.blockSize());
        }
      }
      if (!(lo.x() <= hi.x())) throw std::runtime_error(map_path + ": the map is empty");
      if (!have_center) center = 0.5 * (lo + hi);
      if (size <= 0) size = (hi - lo).maxCoeff();
    }
    fm::OccupancyGridConfig gc;
    gc.size = size;
    gc.resolution = resolution;
    const fm::OccupancyGrid grid = fm::computeOccupancyGrid(map, Eigen::Vector3d(center.x(), center.y(), 0), gc, min_obs);
    std::printf("grid: %d x %d cells of %.2f m around (%.1f, %.1f): %zu occupied, %zu free, %zu unknown\n", grid.width,
                grid.height, grid.resolution, center.x(), center.y(), grid.occupied, grid.free, grid.unknown);

    // The picture: row 0 = highest y.
    cv::Mat img(grid.height, grid.width, CV_8UC3);
    for (int y = 0; y < grid.height; ++y)
      for (int x = 0; x < grid.width; ++x) {
        const int8_t v = grid.at(x, y);
        const uint8_t c = v == fm::OccupancyGrid::kOccupied ? 0 : v == fm::OccupancyGrid::kFree ? 255 : 128;
        img.at<cv::Vec3b>(grid.height - 1 - y, x) = cv::Vec3b(c, c, c);
      }
    std::vector<uint8_t> boundary;
    if (world) {
      auto near_path = [&](double x, double y) {
        for (const auto& p : path) {
          if ((p - Eigen::Vector2d(x, y)).squaredNorm() < within * within) return true;
        }
        return false;
      };
      const fm::OccupancyScore s = fm::scoreOccupancy(
          grid, [&](double x, double y) { return world->occupancyAt(x, y, gc.obstacle_height, gc.vehicle_height); }, 1,
          near_path, &views, &boundary);
      std::printf("within %.0f m of the path: occupied precision %.3f (%zu cells), recall %.3f (%zu boundary cells); "
                  "free precision %.3f (%zu cells), recall %.3f (%zu free cells)\n",
                  within, s.occupiedPrecision(), s.map_occupied, s.occupiedRecall(), s.true_boundary, s.freePrecision(),
                  s.map_free, s.freeRecall(), s.true_free);
      std::printf("visible from the path (ahead, within %.0f m, line of sight): occupied recall %.3f (%zu of the %zu "
                  "boundary cells)\n",
                  views.range, s.visibleRecall(), s.visible_boundary, s.true_boundary);
    }
    // The true obstacles' boundary the score counts: found green, missed
    // magenta, hidden from the path dark violet.
    for (size_t i = 0; i < boundary.size(); ++i) {
      if (!boundary[i]) continue;
      const int x = static_cast<int>(i % grid.width), y = static_cast<int>(i / grid.width);
      img.at<cv::Vec3b>(grid.height - 1 - y, x) = boundary[i] == fm::OccupancyScore::kBoundaryFound    ? cv::Vec3b(0, 170, 0)
                                                  : boundary[i] == fm::OccupancyScore::kBoundaryMissed ? cv::Vec3b(200, 0, 200)
                                                                                                        : cv::Vec3b(110, 50, 90);
    }
    for (const auto& p : path) {
      int cx, cy;
      if (grid.cellOf(p.x(), p.y(), &cx, &cy)) img.at<cv::Vec3b>(grid.height - 1 - cy, cx) = cv::Vec3b(0, 0, 255);
    }
    fm::writeImageFile(png, img);
    std::printf("wrote %s\n", png.c_str());
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "occupancy_eval: " << e.what() << "\n";
    return 1;
  }
}
