// A ground-aware 2D obstacle grid for planners, read from the TSDF map
// (nvblox's costmap slice, but following the ground instead of a fixed
// height): a square of cells around the vehicle, each
//   unknown  (-1)  no ground estimate near it, or nothing seen there;
//   free     (0)   its ground surface was seen, and nothing between
//                  obstacle_height and vehicle_height above the local ground;
//   occupied (100) a surface of the map lies between obstacle_height and
//                  vehicle_height above the local ground.
// Surfaces are the zero crossings of the voxels observed at least
// min_observations times (what the mesh shows). The local ground is
// estimated from the map itself: in each cell the lowest upward-facing
// crossing (free space above, solid below), robustly pooled over 1 m tiles
// (their median) and then over the tiles within ground_radius (a low
// quantile), so slopes and cambers shift it and a car roof or a wall does
// not. Overhangs above vehicle_height (canopies, balconies) leave a cell
// free. Only blocks in memory are read (no swap I/O).
//
// Values follow nav_msgs/OccupancyGrid: row-major, row 0 at the lowest y,
// cell (0, 0)'s corner at `origin` (world x, y).
#ifndef FISHEYE_MAPPING_CORE_TSDF_OCCUPANCY_GRID_H_
#define FISHEYE_MAPPING_CORE_TSDF_OCCUPANCY_GRID_H_

#include <cstdint>
#include <functional>
#include <vector>

#include <Eigen/Core>

namespace fisheye_mapping {

template <class Config>
class ParamTable;  // fisheye_mapping/core/common/param_table.h
class TsdfMap;

struct OccupancyGridConfig {
  double size = 40.0;             // m, side of the square around the vehicle
  double resolution = 0.2;        // m, side of a cell
  double obstacle_height = 0.3;   // m above the local ground: higher surfaces are obstacles
  double vehicle_height = 2.0;    // m above the local ground: higher surfaces are overhangs
  double ground_radius = 2.0;     // m, the tiles pooled into a cell's local ground
  double ground_quantile = 0.25;  // of those tiles' ground heights (low: a roof does not lift the ground)
  double esdf_max_distance = 5.0; // m: the distance field's cap (OccupancyGrid::distance); 0: no field
  // Throws std::invalid_argument naming the parameter (params().check): also
  // for a grid of more than 4000 x 4000 cells, or vehicle_height not above
  // obstacle_height.
  void validate() const;
  // Parameters occupancy_size, occupancy_resolution, ... (docs/parameters.md).
  static const ParamTable<OccupancyGridConfig>& params();
};

struct OccupancyGrid {
  static constexpr int8_t kUnknown = -1, kFree = 0, kOccupied = 100;
  double resolution = 0.2;
  int width = 0, height = 0;                         // cells along x, y
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();  // world x, y of cell (0, 0)'s corner
  std::vector<int8_t> cells;                         // width * height, row-major (y rows)
  std::vector<float> ground;                         // local ground z per cell (world, m); NaN: none
  // The distance field (a 2D ESDF, voxblox's on the grid): per cell the
  // distance (m) from its centre to the nearest occupied cell's centre, 0 on
  // obstacles, at most the cap (esdf_max_distance: no obstacle nearer); NaN
  // at unknown cells. Distances are to the obstacles the map knows: an
  // unknown cell nearer may hide one. Empty when esdf_max_distance is 0.
  std::vector<float> distance;
  size_t occupied = 0, free = 0, unknown = 0;

  int8_t at(int x, int y) const { return cells[static_cast<size_t>(y) * width + x]; }
  // The cell holding world (x, y), false outside.
  bool cellOf(double x, double y, int* cx, int* cy) const;
  Eigen::Vector2d cellCenter(int cx, int cy) const {
    return origin + Eigen::Vector2d((cx + 0.5) * resolution, (cy + 0.5) * resolution);
  }
};

// The grid centred on `center_W` (world x, y; z unused), snapped to whole
// cells. Validates the config (std::invalid_argument naming the parameter).
OccupancyGrid computeOccupancyGrid(TsdfMap& map, const Eigen::Vector3d& center_W, const OccupancyGridConfig& config,
                                   int min_observations);

// Fills grid->distance (see OccupancyGrid) from its cells, capped at
// max_distance (m); max_distance <= 0 leaves it empty. Exact Euclidean
// distances (cv::distanceTransform, DIST_MASK_PRECISE).
void computeDistanceField(OccupancyGrid* grid, double max_distance);

// Where the cameras looked from, for the recall of what they could see:
// positions on the ground, unit headings, how far they see and the half
// angle around the heading they cover (the front rig: a half plane).
struct OccupancyViewpoints {
  std::vector<Eigen::Vector2d> position, heading;
  double range = 20.0;
  double half_fov = 1.5707963267948966;
};

// Grid scores against a truth: truth(x, y) is what the world holds at a cell
// centre (kOccupied, kFree, or kUnknown where it does not say: not scored).
// A map-occupied cell counts as right when the truth has an obstacle within
// `tolerance_cells` (Chebyshev); a true obstacle cell next to a true free cell
// (the obstacles' boundary) counts as found when the map has an occupied cell
// within tolerance_cells. A map-free cell is right when the truth is free
// there. `keep(x, y)`: the cells scored (e.g. within 20 m of the path; the
// truth is asked only there); empty: all.
// With `views`, the boundary cells a camera could see are counted apart
// (visible_boundary): some viewpoint within its range has the cell in its
// field of view and the straight line to it meets no true obstacle beyond
// the cell's own neighbours (1.5 cells); a building's back wall, a parked
// car's far side or a facade behind it are not visible.
// `boundary` (optional) receives, per cell, kBoundaryFound / kBoundaryMissed
// (visible, or all when there are no views) / kBoundaryHidden for the true
// boundary cells and 0 elsewhere (for pictures of what is missed).
struct OccupancyScore {
  static constexpr uint8_t kBoundaryFound = 1, kBoundaryMissed = 2, kBoundaryHidden = 3;
  size_t map_occupied = 0, occupied_right = 0;    // precision of occupied
  size_t true_boundary = 0, boundary_found = 0;   // recall of occupied (all boundary cells)
  size_t visible_boundary = 0, visible_found = 0; // recall of occupied (the boundary cells a camera could see)
  size_t map_free = 0, free_right = 0;            // precision of free
  size_t true_free = 0, free_found = 0;           // recall of free
  double occupiedPrecision() const { return map_occupied ? double(occupied_right) / map_occupied : 0.0; }
  double occupiedRecall() const { return true_boundary ? double(boundary_found) / true_boundary : 0.0; }
  double visibleRecall() const { return visible_boundary ? double(visible_found) / visible_boundary : 0.0; }
  double freePrecision() const { return map_free ? double(free_right) / map_free : 0.0; }
  double freeRecall() const { return true_free ? double(free_found) / true_free : 0.0; }
  OccupancyScore& operator+=(const OccupancyScore& o);
};
OccupancyScore scoreOccupancy(const OccupancyGrid& grid, const std::function<int8_t(double, double)>& truth,
                              int tolerance_cells = 1,
                              const std::function<bool(double, double)>& keep = nullptr,
                              const OccupancyViewpoints* views = nullptr, std::vector<uint8_t>* boundary = nullptr);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_TSDF_OCCUPANCY_GRID_H_
