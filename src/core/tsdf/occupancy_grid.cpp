#include "fisheye_mapping/core/tsdf/occupancy_grid.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <opencv2/imgproc.hpp>

#include "fisheye_mapping/core/common/param_table.h"
#include "fisheye_mapping/core/tsdf/tsdf_map.h"

namespace fisheye_mapping {

const ParamTable<OccupancyGridConfig>& OccupancyGridConfig::params() {
  using C = OccupancyGridConfig;
  using R = ParamRange;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("occupancy");
    t.number("occupancy_size", [](C& c) -> double& { return c.size; }, R::aboveUpTo(0, 1000), "m",
             "Side of the square tsdf/occupancy grid around the vehicle")
        .number("occupancy_resolution", [](C& c) -> double& { return c.resolution; }, R::aboveUpTo(0, 10), "m",
                "Side of a grid cell")
        .number("occupancy_obstacle_height", [](C& c) -> double& { return c.obstacle_height; },
                R::aboveUpTo(0, 10), "m", "Surfaces higher than this above the local ground are obstacles")
        .number("occupancy_vehicle_height", [](C& c) -> double& { return c.vehicle_height; }, R::aboveUpTo(0, 20),
                "m", "Surfaces higher than this above the local ground are overhangs the vehicle passes under")
        .number("occupancy_ground_radius", [](C& c) -> double& { return c.ground_radius; }, R::aboveUpTo(0, 50),
                "m", "The local ground of a cell pools the 1 m ground tiles within this radius")
        .number("occupancy_ground_quantile", [](C& c) -> double& { return c.ground_quantile; }, R::between(0, 1),
                "", "Quantile of those tiles' heights taken as the local ground (low: roofs and walls do not lift it)")
        .number("esdf_max_distance", [](C& c) -> double& { return c.esdf_max_distance; }, R::between(0, 100), "m",
                "Cap of the grid's distance field (tsdf/esdf: distance to the nearest obstacle); 0: none");
    t.rule([](const C& c) {
      const double cells = std::ceil(c.size / c.resolution);
      if (cells > 4000) {
        throw std::invalid_argument("occupancy_size / occupancy_resolution: " + std::to_string(cells) +
                                    " cells per side, at most 4000");
      }
      if (!(c.vehicle_height > c.obstacle_height)) {
        throw std::invalid_argument("occupancy_vehicle_height must be above occupancy_obstacle_height");
      }
    });
    return t;
  }();
  return t;
}

void OccupancyGridConfig::validate() const { params().check(*this); }

bool OccupancyGrid::cellOf(double x, double y, int* cx, int* cy) const {
  const double fx = (x - origin.x()) / resolution, fy = (y - origin.y()) / resolution;
  if (!(fx >= 0 && fy >= 0 && fx < width && fy < height)) return false;
  *cx = static_cast<int>(fx);
  *cy = static_cast<int>(fy);
  return true;
}

namespace {

// A zero crossing of the map: height, and whether it faces up (free space
// above, solid below, on a vertical edge of the voxel grid).
struct Crossing {
  float z;
  bool up;
};

float quantile(std::vector<float>* v, double q) {
  if (v->empty()) return std::numeric_limits<float>::quiet_NaN();
  const size_t k = std::min(v->size() - 1, static_cast<size_t>(q * (v->size() - 1) + 0.5));
  std::nth_element(v->begin(), v->begin() + static_cast<long>(k), v->end());
  return (*v)[k];
}

}  // namespace

OccupancyGrid computeOccupancyGrid(TsdfMap& map, const Eigen::Vector3d& center_W, const OccupancyGridConfig& config,
                                   int min_observations) {
  config.validate();
  OccupancyGrid g;
  g.resolution = config.resolution;
  g.width = g.height = static_cast<int>(std::ceil(config.size / config.resolution));
  // Snapped to whole cells, so that the grid does not shimmer as the car moves.
  const double half = 0.5 * g.width * g.resolution;
  g.origin = Eigen::Vector2d(std::floor((center_W.x() - half) / g.resolution) * g.resolution,
                             std::floor((center_W.y() - half) / g.resolution) * g.resolution);
  const size_t n = static_cast<size_t>(g.width) * g.height;
  g.cells.assign(n, OccupancyGrid::kUnknown);
  g.ground.assign(n, std::numeric_limits<float>::quiet_NaN());

  // 1. Every zero crossing of the observed voxels above the grid, by cell.
  std::vector<std::vector<Crossing>> column(n);
  const double vs = map.config().voxel_size;
  const float min_w = minObservationWeight(min_observations);
  const BlockStore& store = map.store();
  const double bs = map.config().blockSize();
  auto value = [&](const Eigen::Vector3i& gv, float* out) {
    const BlockIndex b(static_cast<int>(std::floor(double(gv.x()) / FM_BLOCK_SIDE)),
                       static_cast<int>(std::floor(double(gv.y()) / FM_BLOCK_SIDE)),
                       static_cast<int>(std::floor(double(gv.z()) / FM_BLOCK_SIDE)));
    const VoxelBlock* blk = store.find(b);
    if (!blk) return false;
    const Eigen::Vector3i l = gv - b * FM_BLOCK_SIDE;
    const FmVoxel& v = blk->voxels[VoxelBlock::linear(l.x(), l.y(), l.z())];
    if (!(v.weight >= min_w)) return false;
    *out = v.tsdf;
    return true;
  };
  for (const BlockIndex& b : map.allBlocks()) {
    const VoxelBlock* blk = store.find(b);
    if (!blk) continue;
    const double bx = b.x() * bs, by = b.y() * bs;
    if (bx + bs < g.origin.x() || by + bs < g.origin.y() || bx > g.origin.x() + g.width * g.resolution ||
        by > g.origin.y() + g.height * g.resolution) {
      continue;
    }
    for (int k = 0; k < FM_BLOCK_SIDE; ++k)
      for (int j = 0; j < FM_BLOCK_SIDE; ++j)
        for (int i = 0; i < FM_BLOCK_SIDE; ++i) {
          const FmVoxel& v0 = blk->voxels[VoxelBlock::linear(i, j, k)];
          if (!(v0.weight >= min_w)) continue;
          const Eigen::Vector3i gv = b * FM_BLOCK_SIDE + Eigen::Vector3i(i, j, k);
          const int l[3] = {i, j, k};
          for (int axis = 0; axis < 3; ++axis) {
            Eigen::Vector3i gn = gv;
            gn[axis] += 1;
            float d1;
            if (l[axis] + 1 < FM_BLOCK_SIDE) {  // inside this block: no lookup
              const FmVoxel& v1 = blk->voxels[VoxelBlock::linear(i + (axis == 0), j + (axis == 1), k + (axis == 2))];
              if (!(v1.weight >= min_w)) continue;
              d1 = v1.tsdf;
            } else if (!value(gn, &d1)) {
              continue;
            }
            const float d0 = v0.tsdf;
            if ((d0 < 0) == (d1 < 0)) continue;
            const float t = d0 / (d0 - d1);
            Eigen::Vector3d p = (gv.cast<double>() + Eigen::Vector3d::Constant(0.5)) * vs;
            p[axis] += t * vs;
            int cx, cy;
            if (!g.cellOf(p.x(), p.y(), &cx, &cy)) continue;
            // Up-facing: positive (free) above, negative below.
            column[static_cast<size_t>(cy) * g.width + cx].push_back({static_cast<float>(p.z()), axis == 2 && d1 > 0});
          }
        }
  }

  // 2. Ground candidates: each cell's lowest up-facing crossing; pooled into
  // 1 m tiles (median), then per cell a low quantile of the tiles within
  // ground_radius.
  std::vector<float> candidate(n, std::numeric_limits<float>::quiet_NaN());
  for (size_t c = 0; c < n; ++c) {
    for (const Crossing& x : column[c]) {
      if (x.up && !(x.z >= candidate[c])) candidate[c] = x.z;  // NaN compares false: the first one wins
    }
  }
  const int tile = std::max(1, static_cast<int>(std::lround(1.0 / g.resolution)));
  const int tw = (g.width + tile - 1) / tile, th = (g.height + tile - 1) / tile;
  std::vector<float> tile_ground(static_cast<size_t>(tw) * th, std::numeric_limits<float>::quiet_NaN());
  std::vector<float> pool;
  for (int ty = 0; ty < th; ++ty)
    for (int tx = 0; tx < tw; ++tx) {
      pool.clear();
      for (int y = ty * tile; y < std::min(g.height, (ty + 1) * tile); ++y)
        for (int x = tx * tile; x < std::min(g.width, (tx + 1) * tile); ++x) {
          const float z = candidate[static_cast<size_t>(y) * g.width + x];
          if (z == z) pool.push_back(z);
        }
      tile_ground[static_cast<size_t>(ty) * tw + tx] = quantile(&pool, 0.5);
    }
  const double tile_m = tile * g.resolution;
  const int r_tiles = static_cast<int>(std::ceil(config.ground_radius / tile_m));
  std::vector<float> local(static_cast<size_t>(tw) * th, std::numeric_limits<float>::quiet_NaN());
  for (int ty = 0; ty < th; ++ty)
    for (int tx = 0; tx < tw; ++tx) {
      pool.clear();
      for (int dy = -r_tiles; dy <= r_tiles; ++dy)
        for (int dx = -r_tiles; dx <= r_tiles; ++dx) {
          const int x = tx + dx, y = ty + dy;
          if (x < 0 || y < 0 || x >= tw || y >= th) continue;
          if ((dx * dx + dy * dy) * tile_m * tile_m > config.ground_radius * config.ground_radius + 1e-9) continue;
          const float z = tile_ground[static_cast<size_t>(y) * tw + x];
          if (z == z) pool.push_back(z);
        }
      local[static_cast<size_t>(ty) * tw + tx] = quantile(&pool, config.ground_quantile);
    }

  // 3. Cells: occupied by a surface between the two heights over the local
  // ground; free where the ground itself was seen; unknown otherwise.
  const float lo = static_cast<float>(config.obstacle_height), hi = static_cast<float>(config.vehicle_height);
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) {
      const size_t c = static_cast<size_t>(y) * g.width + x;
      const float ground = local[static_cast<size_t>(y / tile) * tw + x / tile];
      g.ground[c] = ground;
      if (!(ground == ground)) continue;  // no ground near: unknown
      bool obstacle = false, seen_ground = false;
      for (const Crossing& xg : column[c]) {
        const float h = xg.z - ground;
        if (h > lo && h <= hi) obstacle = true;
        if (xg.up && std::abs(h) <= lo) seen_ground = true;
      }
      if (obstacle) {
        g.cells[c] = OccupancyGrid::kOccupied;
      } else if (seen_ground) {
        g.cells[c] = OccupancyGrid::kFree;
      }
    }
  for (int8_t v : g.cells) {
    if (v == OccupancyGrid::kOccupied) ++g.occupied;
    else if (v == OccupancyGrid::kFree) ++g.free;
    else ++g.unknown;
  }
  computeDistanceField(&g, config.esdf_max_distance);
  return g;
}

void computeDistanceField(OccupancyGrid* grid, double max_distance) {
  OccupancyGrid& g = *grid;
  g.distance.clear();
  if (!(max_distance > 0) || g.width <= 0 || g.height <= 0) return;
  // distanceTransform: each non-zero pixel's distance to the nearest zero one.
  cv::Mat src(g.height, g.width, CV_8UC1);
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) src.at<uint8_t>(y, x) = g.at(x, y) == OccupancyGrid::kOccupied ? 0 : 255;
  cv::Mat dist;
  if (cv::countNonZero(src) < static_cast<int>(src.total())) {  // an obstacle to be near
    cv::distanceTransform(src, dist, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
  } else {
    dist = cv::Mat(g.height, g.width, CV_32F, cv::Scalar(std::numeric_limits<float>::infinity()));
  }
  const float cap = static_cast<float>(max_distance);
  g.distance.resize(g.cells.size());
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) {
      const size_t i = static_cast<size_t>(y) * g.width + x;
      g.distance[i] = g.cells[i] == OccupancyGrid::kUnknown
                          ? std::numeric_limits<float>::quiet_NaN()
                          : std::min(cap, static_cast<float>(dist.at<float>(y, x) * g.resolution));
    }
}

OccupancyScore& OccupancyScore::operator+=(const OccupancyScore& o) {
  map_occupied += o.map_occupied, occupied_right += o.occupied_right;
  true_boundary += o.true_boundary, boundary_found += o.boundary_found;
  visible_boundary += o.visible_boundary, visible_found += o.visible_found;
  map_free += o.map_free, free_right += o.free_right;
  true_free += o.true_free, free_found += o.free_found;
  return *this;
}

OccupancyScore scoreOccupancy(const OccupancyGrid& grid, const std::function<int8_t(double, double)>& truth,
                              int tolerance_cells, const std::function<bool(double, double)>& keep,
                              const OccupancyViewpoints* views, std::vector<uint8_t>* boundary) {
  const int w = grid.width, h = grid.height;
  if (boundary) boundary->assign(static_cast<size_t>(w) * h, 0);
  std::vector<int8_t> t(static_cast<size_t>(w) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Eigen::Vector2d c = grid.cellCenter(x, y);
      // Cells not scored are not asked (the truth may be costly).
      t[static_cast<size_t>(y) * w + x] = keep && !keep(c.x(), c.y()) ? OccupancyGrid::kUnknown : truth(c.x(), c.y());
    }
  auto near = [&](const std::vector<int8_t>& v, int x, int y, int8_t what, int r) {
    for (int dy = -r; dy <= r; ++dy)
      for (int dx = -r; dx <= r; ++dx) {
        const int a = x + dx, b = y + dy;
        if (a >= 0 && b >= 0 && a < w && b < h && v[static_cast<size_t>(b) * w + a] == what) return true;
      }
    return false;
  };
  // A camera at a viewpoint sees the cell centre c: in range, in its field of
  // view, and the line to it clear of true obstacles past c's neighbours.
  const double cos_fov = views ? std::cos(views->half_fov) : 1.0;
  auto visible = [&](const Eigen::Vector2d& c) {
    for (size_t k = 0; k < views->position.size(); ++k) {
      const Eigen::Vector2d d = views->position[k] - c;
      const double len = d.norm();
      if (!(len <= views->range) || len < 1e-9) continue;
      if (-d.dot(views->heading[k]) < cos_fov * len) continue;
      bool clear = true;
      for (double step = 1.5 * grid.resolution; step < len && clear; step += 0.5 * grid.resolution) {
        int cx, cy;
        const Eigen::Vector2d p = c + d * (step / len);
        if (grid.cellOf(p.x(), p.y(), &cx, &cy) && t[static_cast<size_t>(cy) * w + cx] == OccupancyGrid::kOccupied) {
          clear = false;
        }
      }
      if (clear) return true;
    }
    return false;
  };
  OccupancyScore s;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Eigen::Vector2d c = grid.cellCenter(x, y);
      if (keep && !keep(c.x(), c.y())) continue;
      const size_t i = static_cast<size_t>(y) * w + x;
      const int8_t m = grid.cells[i], tv = t[i];
      if (m == OccupancyGrid::kOccupied && tv != OccupancyGrid::kUnknown) {
        ++s.map_occupied;
        s.occupied_right += near(t, x, y, OccupancyGrid::kOccupied, tolerance_cells);
      }
      if (m == OccupancyGrid::kFree && tv != OccupancyGrid::kUnknown) {
        ++s.map_free;
        s.free_right += tv == OccupancyGrid::kFree;
      }
      if (tv == OccupancyGrid::kOccupied && near(t, x, y, OccupancyGrid::kFree, 1)) {
        ++s.true_boundary;
        const bool found = near(grid.cells, x, y, OccupancyGrid::kOccupied, tolerance_cells);
        s.boundary_found += found;
        const bool seen = !views || visible(c);
        if (views && seen) {
          ++s.visible_boundary;
          s.visible_found += found;
        }
        if (boundary) {
          (*boundary)[i] = found ? OccupancyScore::kBoundaryFound
                                 : seen ? OccupancyScore::kBoundaryMissed : OccupancyScore::kBoundaryHidden;
        }
      }
      if (tv == OccupancyGrid::kFree) {
        ++s.true_free;
        s.free_found += m == OccupancyGrid::kFree;
      }
    }
  return s;
}

}  // namespace fisheye_mapping
