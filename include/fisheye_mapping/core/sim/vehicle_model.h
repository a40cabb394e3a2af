// Vehicles of the synthetic world: cars, vans, trucks and buses built from a
// few convex parts (a chamfered lower body, a greenhouse with sloped
// windscreen and rear window, a truck's cab and cargo box) and four or more
// wheels, so that a detector trained on COCO sees more than two boxes: glass
// darker and smoother than the paint (a little sky reflected), wheels (dark
// tyres, lighter hubs) in dark wheel arches, head lights (bright) and tail
// lights (dark), bumpers and grille (dark trim). Convex parts are
// intersections of half-spaces, so a ray costs one slab test per plane; a
// bounding box test comes first.
//
// Vehicle frame: x forward, y left, z up, origin on the ground at the centre
// of the footprint.
#ifndef FISHEYE_MAPPING_CORE_SIM_VEHICLE_MODEL_H_
#define FISHEYE_MAPPING_CORE_SIM_VEHICLE_MODEL_H_

#include <array>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>

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
  kCarPaint,  // a vehicle's body paint
  kGlass,     // windows: dark grey, smooth, a little sky reflected
  kTyre,
  kHub,       // wheel hub / rim: lighter than the tyre
  kTrim,      // bumpers, grille, sills, wheel arches: dark plastic
  kLight,     // head lights (bright) and tail lights (dark)
};

enum class VehicleKind : uint8_t { kCar = 0, kVan, kTruck, kBus };
constexpr int kNumVehicleKinds = 4;
// "car", "van", "truck", "bus": the dataset's classes, in this order (id = kind).
const char* kindName(VehicleKind kind);
// The COCO class a COCO-trained detector should give it: a van is a "car" (as
// COCO's annotators mostly label vans), a truck a "truck", a bus a "bus".
const char* cocoName(VehicleKind kind);
// Its 0-based index in COCO's 80-class list (coco.names): car 2, bus 5, truck 7.
int cocoId(VehicleKind kind);

// Size and paint of one vehicle.
struct VehicleDims {
  VehicleKind kind = VehicleKind::kCar;
  double length = 4.5, width = 1.8, height = 1.45;  // metres
  float paint = 0.6f;   // body albedo
  float paint2 = 0.8f;  // a truck's cargo box
};
// Sizes drawn uniformly from each kind's real range (length: car 4.2-4.8 m,
// van 4.8-5.6, truck 7-10, bus 11-12; widths and heights to match) and a grey
// paint level.
VehicleDims drawVehicle(VehicleKind kind, std::mt19937& rng);

class VehicleModel {
 public:
  explicit VehicleModel(const VehicleDims& dims);

  struct LocalHit {
    double t = 0;
    Eigen::Vector3d n;       // unit normal, vehicle frame
    Material material = kCarPaint;
    float albedo = 0.0f;
  };
  // First surface along the ray (o, unit d; vehicle frame) at t in (0, t_max).
  bool intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_max, LocalHit* hit) const;
  // Signed distance to the surface, exact inside and on the faces, a lower
  // bound near edges (for scoring maps against the scene).
  double distance(const Eigen::Vector3d& p) const;
  // The surface as triangles (vehicle frame), for the static scene mesh.
  std::vector<std::array<Eigen::Vector3d, 3>> triangles() const;

  const VehicleDims& dims() const { return dims_; }
  const Eigen::Vector3d& boundsLo() const { return lo_; }
  const Eigen::Vector3d& boundsHi() const { return hi_; }
  double radius() const { return radius_; }  // of a sphere about the origin holding it
  double wheelRadius() const { return wheel_r_; }
  // Centres of the wheels' outer faces (vehicle frame).
  std::vector<Eigen::Vector3d> wheelCentres() const;

 private:
  // Convex part: points with n.x <= d for every plane (n, d).
  struct Convex {
    std::vector<Eigen::Vector4d> planes;
    Eigen::Vector3d lo, hi;
    int role;
  };
  // Wheel: cylinder about an axis parallel to y.
  struct Wheel {
    Eigen::Vector3d c;  // centre (middle of the tread)
    double r, half_w;
    double outer_sign;  // +1: outer face towards +y
  };
  static Convex box(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, int role);
  // Cuts away the side of the plane through p with outward normal n.
  static void cut(Convex* c, const Eigen::Vector3d& n, const Eigen::Vector3d& p);
  void buildCar();
  void buildVan();
  void buildTruck();
  void buildBus();
  void addWheels(const std::vector<double>& axles_x, double r);
  Material surface(int role, int face, const Eigen::Vector3d& p, const Eigen::Vector3d& n,
                   const Eigen::Vector3d& d, float* albedo) const;
  float glassAlbedo(const Eigen::Vector3d& n, const Eigen::Vector3d& d) const;

  VehicleDims dims_;
  std::vector<Convex> parts_;
  std::vector<Wheel> wheels_;
  Eigen::Vector3d lo_, hi_;
  double radius_ = 0;
  double wheel_r_ = 0.3;
  // Appearance constants of the kind (vehicle frame): belt line, lights' and
  // bumpers' heights, glass bands.
  double clearance_ = 0.2, belt_ = 0.9, light_z_ = 0.7, bumper_top_ = 0.45;
  double windscreen_x0_ = 0, windscreen_x1_ = 0, rear_x0_ = 0, rear_x1_ = 0;
};

}  // namespace synth
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_SIM_VEHICLE_MODEL_H_
