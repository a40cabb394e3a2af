// A procedural driving world with exact ground truth, for synthetic logged
// drives: a Manhattan grid of streets (urban preset: building blocks with
// facades, windows, poles, parked cars; forest preset: trees along the road),
// an ego route with rounded turns, and moving vehicles (oncoming and
// overtaking) on the ego's road. Rendering casts one ray per pixel through any
// camera model: Lambertian shading of world-space textures, so every camera
// sees the same surface, plus mild noise and vignetting; depth is the exact
// range along the ray (NaN for sky). Deterministic for a seed.
//
// Thread-safe for concurrent const calls (render from several threads).
#ifndef FISHEYE_MAPPING_CORE_SYNTHETIC_WORLD_H_
#define FISHEYE_MAPPING_CORE_SYNTHETIC_WORLD_H_

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera_model.h"

namespace fisheye_mapping {
namespace synth {

enum Material : uint8_t {
  kSky = 0,
  kAsphalt,
  kKerb,
  kSidewalk,
  kGrass,
  kBrick,
  kPlaster,
  kFoliage,
  kBark,
  kMetal,
  kCarPaint,
};

struct WorldConfig {
  std::string preset = "urban";  // "urban" | "forest" | "flat" (ground only, for tests)
  uint32_t seed = 1;
  double route_length = 400.0;   // metres of ego route to furnish
  double speed = 8.0;            // ego speed, m/s
  int moving_vehicles = 6;       // half oncoming, half overtaking
  // Throws std::invalid_argument naming the field.
  void validate() const;
};

// An axis-aligned box, or (yaw != 0 / moving) an oriented one.
struct Box {
  Eigen::Vector3d lo, hi;  // in the box frame (world for static boxes)
  Material material;
  float albedo;            // base brightness in [0, 1]
  int object = -1;         // moving-vehicle id, -1 for the static scene
};

struct Sphere {
  Eigen::Vector3d c;
  double r;
  Material material;
  float albedo;
};

struct MovingVehicle {
  double s0;        // arc length along the route at t = 0
  double speed;     // m/s along the route (negative: driving against it)
  double lateral;   // metres left of the route centreline
  float albedo;
};

struct Hit {
  double t = std::numeric_limits<double>::infinity();  // range along the unit ray
  Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
  Material material = kSky;
  float albedo = 0.0f;
  int object = -1;  // moving-vehicle id or -1
};

class World {
 public:
  explicit World(const WorldConfig& config);

  const WorldConfig& config() const { return config_; }
  // base_link pose (REP 103, origin on the ground) of the ego at time t.
  Eigen::Isometry3d egoPose(double t) const;
  // Pose of moving vehicle i (its base, centre of the footprint) at time t.
  Eigen::Isometry3d vehiclePose(int i, double t) const;
  int numVehicles() const { return static_cast<int>(vehicles_.size()); }

  // First surface along the ray (o, unit d) at time t, up to max_range.
  Hit cast(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double time, double max_range = 250.0) const;
  // The same with the vehicles' poses at the time given (vehiclePoses(time)),
  // for casting many rays at one instant.
  std::vector<Eigen::Isometry3d> vehiclePoses(double time) const;
  Hit cast(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const std::vector<Eigen::Isometry3d>& vehicles,
           double max_range = 250.0) const;

  struct Frame {
    cv::Mat image;  // CV_8UC1
    cv::Mat depth;  // CV_32FC1, range along the ray, NaN for sky / invalid pixels
    cv::Mat ids;    // CV_16SC1, moving-vehicle id per pixel, -1 elsewhere
  };
  // Renders one camera at pose T_W_C and time t; noise_seed makes the sensor
  // noise deterministic. Uses all cores.
  // rays: pixelRays(camera), computed once per camera.
  Frame render(const CameraModel& camera, const std::vector<Eigen::Vector3f>& rays,
               const Eigen::Isometry3d& T_W_C, double time, uint64_t noise_seed) const;

  // The static scene as a triangle mesh (binary PLY), for map evaluation.
  void saveStaticMeshPly(const std::string& path) const;

  const std::vector<Box>& staticBoxes() const { return boxes_; }
  const std::vector<Sphere>& staticSpheres() const { return spheres_; }

  // Street geometry (shared by the texture of the ground and the builder).
  static constexpr double kBlock = 90.0;        // street spacing
  // Four 3.5 m lanes (two each way) and a parking strip on both sides. The ego
  // drives in the right lane; overtaking vehicles pass it in the inner lane,
  // oncoming ones use the other two.
  static constexpr double kRoadHalfWidth = 9.0;
  static constexpr double kLane = 3.5;
  static constexpr double kSidewalk = 3.0;

 private:
  void build();
  void buildRoute();
  void addStreetSide(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& left, uint64_t key);
  void indexGrid();
  Eigen::Vector3d routePoint(double s, Eigen::Vector2d* tangent) const;
  float shade(const Hit& h, const Eigen::Vector3d& p) const;

  WorldConfig config_;
  std::vector<Eigen::Vector2d> waypoints_;  // route corners
  std::vector<double> cumulative_;          // arc length at each corner (straight segments)
  std::vector<Box> boxes_;
  std::vector<Sphere> spheres_;
  std::vector<MovingVehicle> vehicles_;
  // Uniform grid over x-y: each cell lists static boxes (>= 0) and spheres (~index).
  double cell_ = 8.0;
  Eigen::Vector2d grid_min_;
  int grid_w_ = 0, grid_h_ = 0;
  std::vector<std::vector<int>> cells_;
};

}  // namespace synth
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_SYNTHETIC_WORLD_H_
