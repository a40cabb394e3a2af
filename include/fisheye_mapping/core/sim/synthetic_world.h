// A procedural driving world with exact ground truth, for synthetic logged
// drives: a Manhattan grid of streets (urban preset: building blocks with
// facades, windows, poles, parked vehicles along the kerbs, some angled;
// forest preset: trees along the road), an ego route with rounded turns, and
// moving vehicles (oncoming and overtaking) on the ego's road. Vehicles are
// cars, vans, trucks and buses with shaped bodies, glass, wheels and lights
// (vehicle_model.h). Rendering casts one ray per pixel through any
// camera model: Lambertian shading of world-space textures, so every camera
// sees the same surface, through a sensor model (by default mild noise and
// vignetting, identical cameras; optionally per-camera gain / offset / gamma,
// shot noise and blur, and a perturbed calibration to hand the pipeline);
// depth is the exact range along the ray (NaN for sky). Deterministic for a
// seed.
//
// Thread-safe for concurrent const calls (render from several threads).
#ifndef FISHEYE_MAPPING_CORE_SIM_SYNTHETIC_WORLD_H_
#define FISHEYE_MAPPING_CORE_SIM_SYNTHETIC_WORLD_H_

#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/camera_model.h"
#include "fisheye_mapping/core/camera/rig.h"
#include "fisheye_mapping/core/sim/vehicle_model.h"

namespace fisheye_mapping {
namespace synth {

struct WorldConfig {
  std::string preset = "urban";  // "urban" | "forest" | "flat" (ground only, for tests)
  uint32_t seed = 1;
  double route_length = 400.0;   // metres of ego route to furnish
  double speed = 8.0;            // ego speed, m/s
  int moving_vehicles = 6;       // half oncoming, half overtaking
  // Realism (0: off). Pixel-scale grain of the asphalt (albedo amplitude of
  // 1-2.5 cm value noise, on top of the road's blotches) and low-contrast
  // clouds in the sky (intensity amplitude; at infinity).
  double asphalt_grain = 0.0;
  double clouds = 0.0;
  // An overcast sky as contrasted as a real one (make_drive --cloudy-sky):
  // the clouds get detail down to about a degree (six octaves of value noise,
  // 2 to 64 cycles per radian) and soft edges. With amplitude `clouds` =
  // kOvercastClouds, 9x9 windows of the sky in a 1024 px wide fisheye image
  // have a median standard deviation of ~0.009 before sensor noise, as clean
  // patches of the real overcast sky of shared/data/vcharge_fisheye (right
  // sequence, 0.008-0.011, its noise 0.002) have.
  bool overcast = false;
  static constexpr double kOvercastClouds = 0.3;
  // Throws std::invalid_argument naming the field.
  void validate() const;
};

// One camera's sensor and lens, applied to the rendered radiance I in [0, 1]:
//   I_v = I * max(1 - 1.5 vignetting, 1 - vignetting * (angle / 90 deg)^2)
//   I_b = Gaussian blur of I_v (sigma blur_px)
//   DN  = offset + 255 * clamp(gain * I_b, 0, 1)^gamma
//       + N(0, read_noise^2 + shot_noise * DN) clamped to [0, 255]
// The defaults are the exact drives' sensor (identical cameras, 1.5 DN noise).
struct SensorModel {
  double gain = 1.0;
  double offset = 0.0;        // DN
  double gamma = 1.0;
  double vignetting = 0.3;
  double blur_px = 0.0;
  double read_noise = 1.5;    // DN
  double shot_noise = 0.0;    // noise variance per DN of signal
  // Throws std::invalid_argument naming the field.
  void validate() const;
};

// Per-camera differences of a realistic rig, drawn from a seed.
struct SensorSpread {
  double gain = 0.0;          // gain uniform in 1 +- gain
  double offset = 0.0;        // offset uniform in +- offset DN
  double gamma = 0.0;         // gamma uniform in 1 +- gamma
  SensorModel base;           // vignetting, blur and noise of every camera
};
// The sensors of `cameras` cameras: camera i from (seed, i) alone.
std::vector<SensorModel> drawSensors(const SensorSpread& spread, int cameras, uint64_t seed);

// Everything that makes a synthetic drive as hard as a real rig's, in one
// place for make_drive and depth_eval. Default: an exact drive.
struct Realism {
  double calib_rot_deg = 0.0;   // calibration error std. dev. per axis (drawExtrinsicErrors)
  double calib_trans_mm = 0.0;
  SensorSpread sensors;         // per-camera response, noise, blur (drawSensors)
  double asphalt_grain = 0.0;   // WorldConfig
  double clouds = 0.0;
  // The "realistic" setting: 0.3 deg / 5 mm calibration error, gain +-20 %,
  // black level +-4 DN, gamma +-10 %, vignetting 0.45, read noise 2 DN, shot
  // noise 0.03 DN per DN, blur 0.7 px, asphalt grain 0.08, clouds 0.06.
  static Realism realistic();
};

// A calibration error: what a rig's calibration says differs from the truth
// by a small rigid motion of each supporting camera relative to the
// reference (camera 0; its mount on the car stays exact).
struct ExtrinsicError {
  Eigen::Vector3d rotation_deg = Eigen::Vector3d::Zero();  // axis-angle, degrees
  Eigen::Vector3d translation_mm = Eigen::Vector3d::Zero();
};
// Normal per-axis errors of std. dev. rot_sigma_deg and trans_sigma_mm for
// cameras 1.., zero for camera 0; camera i from (seed, i) alone.
std::vector<ExtrinsicError> drawExtrinsicErrors(int cameras, double rot_sigma_deg, double trans_sigma_mm,
                                                    uint64_t seed);
// The calibration a pipeline would be given: T_cam0_cam' = T_cam0_cam * dT,
// dT = (exp(rotation), translation) in the camera's own frame; T_base_cam
// follows from the unchanged T_base_cam0.
Rig perturbRig(const Rig& truth, const std::vector<ExtrinsicError>& errors);

// An axis-aligned box, or (yaw != 0 / moving) an oriented one.
struct Box {
  Eigen::Vector3d lo, hi;  // in the box frame (world for static boxes)
  Material material;
  float albedo;            // base brightness in [0, 1]
  int object = -1;         // unused (static scene)
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
  float albedo;     // body paint
};

struct Hit {
  double t = std::numeric_limits<double>::infinity();  // range along the unit ray
  Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
  Material material = kSky;
  float albedo = 0.0f;
  int object = -1;  // vehicle id or -1
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

  // Every vehicle, moving or parked, has an id: the moving ones 0 ..
  // numVehicles() - 1 (as vehiclePose), the parked ones after them.
  int numVehicleIds() const { return static_cast<int>(models_.size()); }
  bool isMoving(int id) const { return id < numVehicles(); }
  const VehicleModel& vehicleModel(int id) const { return models_.at(id); }
  // Pose of vehicle `id` at time t (parked ones: fixed).
  Eigen::Isometry3d vehiclePoseById(int id, double t) const;
  // Parks one more vehicle (for scenes built by hand, e.g. in tests); returns its id.
  int addParkedVehicle(const VehicleDims& dims, const Eigen::Isometry3d& pose);

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
    cv::Mat ids;    // CV_16SC1, vehicle id per pixel (moving < numVehicles() <= parked), -1 elsewhere
    cv::Mat materials;  // CV_8UC1, Material per pixel
  };
  // Renders one camera at pose T_W_C and time t; noise_seed makes the sensor
  // noise deterministic. Uses all cores.
  // rays: pixelRays(camera), computed once per camera.
  Frame render(const CameraModel& camera, const std::vector<Eigen::Vector3f>& rays,
               const Eigen::Isometry3d& T_W_C, double time, uint64_t noise_seed,
               const SensorModel& sensor = SensorModel()) const;

  // Ground truth of a planner's obstacle grid (OccupancyGrid's values) at
  // world (x, y), for the static scene with its parked vehicles (moving
  // vehicles are left out): 100 (occupied) when a solid lies in the column
  // between obstacle_height and vehicle_height above the ground (z = 0);
  // 0 (free) when the ground (road, kerb, pavement below obstacle_height) is
  // the first surface under vehicle_height and nothing else is there; -1 when
  // there is no ground.
  int8_t occupancyAt(double x, double y, double obstacle_height, double vehicle_height) const;
  // The static scene as a triangle mesh (binary PLY, through writeFileSafely),
  // for map evaluation.
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
  void addParkedRow(const Eigen::Vector2d& a, const Eigen::Vector2d& dir, const Eigen::Vector2d& left, double len,
                    std::mt19937& rng);
  bool castVehicle(int id, const Eigen::Isometry3d& T_W_V, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                   Hit* best) const;
  float groundShadow(const Eigen::Vector3d& p, const std::vector<Eigen::Isometry3d>& vehicles) const;
  Eigen::Vector3d routePoint(double s, Eigen::Vector2d* tangent) const;
  float shade(const Hit& h, const Eigen::Vector3d& p) const;

  WorldConfig config_;
  std::vector<Eigen::Vector2d> waypoints_;  // route corners
  std::vector<double> cumulative_;          // arc length at each corner (straight segments)
  std::vector<Box> boxes_;
  std::vector<Sphere> spheres_;
  std::vector<MovingVehicle> vehicles_;
  std::vector<VehicleModel> models_;             // by vehicle id
  std::vector<Eigen::Isometry3d> parked_poses_;  // id numVehicles() + j
  // Uniform grid over x-y: each cell lists static boxes (0 .. boxes - 1),
  // parked vehicles (boxes + j) and spheres (~index).
  double cell_ = 8.0;
  Eigen::Vector2d grid_min_;
  int grid_w_ = 0, grid_h_ = 0;
  std::vector<std::vector<int>> cells_;
};

}  // namespace synth
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_SIM_SYNTHETIC_WORLD_H_
