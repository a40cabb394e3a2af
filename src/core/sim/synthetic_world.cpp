#include "fisheye_mapping/core/sim/synthetic_world.h"

#include <pcl/PolygonMesh.h>
#include <pcl/conversions.h>
#include <pcl/io/ply_io.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <stdexcept>

#include "fisheye_mapping/core/common/safe_write.h"

namespace fisheye_mapping {
namespace synth {
namespace {

constexpr double kTurnRadius = 10.0;

// Deterministic lattice hash in [0, 1].
inline float hash3(int x, int y, int z, uint32_t seed) {
  uint32_t h = seed ^ (static_cast<uint32_t>(x) * 73856093u) ^ (static_cast<uint32_t>(y) * 19349663u) ^
               (static_cast<uint32_t>(z) * 83492791u);
  h ^= h >> 13;
  h *= 0x5bd1e995u;
  h ^= h >> 15;
  return static_cast<float>(h & 0xffffff) / 16777215.0f;
}

// Smooth value noise in [0, 1].
float noise(const Eigen::Vector3d& p, uint32_t seed) {
  const Eigen::Vector3d f = p.array().floor();
  const int x = static_cast<int>(f.x()), y = static_cast<int>(f.y()), z = static_cast<int>(f.z());
  Eigen::Vector3d r = p - f;
  r = r.array() * r.array() * (3.0 - 2.0 * r.array());
  float c[2][2][2];
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j)
      for (int k = 0; k < 2; ++k) c[i][j][k] = hash3(x + i, y + j, z + k, seed);
  auto lerp = [](float a, float b, double t) { return static_cast<float>(a + (b - a) * t); };
  const float x00 = lerp(c[0][0][0], c[1][0][0], r.x()), x10 = lerp(c[0][1][0], c[1][1][0], r.x());
  const float x01 = lerp(c[0][0][1], c[1][0][1], r.x()), x11 = lerp(c[0][1][1], c[1][1][1], r.x());
  return lerp(lerp(x00, x10, r.y()), lerp(x01, x11, r.y()), r.z());
}

float fbm(const Eigen::Vector3d& p, uint32_t seed) {
  return 0.5f * noise(p, seed) + 0.3f * noise(2.03 * p, seed + 1) + 0.2f * noise(4.1 * p, seed + 2);
}

// Overcast clouds along the direction d (unit), in [0, 1]: six octaves of
// value noise from 2 to 64 cycles per radian, amplitudes falling by 0.6 per
// octave, through a soft threshold (cloud edges).
float overcastClouds(const Eigen::Vector3d& d, uint32_t seed) {
  float sum = 0.0f, norm = 0.0f, amplitude = 1.0f;
  double frequency = 2.0;
  for (int octave = 0; octave < 6; ++octave) {
    sum += amplitude * noise(frequency * d, seed + 100 + octave);
    norm += amplitude;
    amplitude *= 0.6f;
    frequency *= 2.0;
  }
  const float x = std::clamp((sum / norm - 0.35f) / 0.3f, 0.0f, 1.0f);
  return x * x * (3.0f - 2.0f * x);
}

// Ray against an axis-aligned box: entry distance and face normal.
bool rayBox(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& lo,
            const Eigen::Vector3d& hi, double* t_hit, Eigen::Vector3d* n) {
  double t0 = 1e-6, t1 = std::numeric_limits<double>::infinity();
  int axis = -1;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-12) {
      if (o[a] < lo[a] || o[a] > hi[a]) return false;
      continue;
    }
    double ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    if (ta > t0) t0 = ta, axis = a;
    t1 = std::min(t1, tb);
    if (t0 > t1) return false;
  }
  if (axis < 0) return false;  // origin inside
  *t_hit = t0;
  *n = Eigen::Vector3d::Zero();
  (*n)[axis] = d[axis] > 0 ? -1.0 : 1.0;
  return true;
}

// Kinds of the moving vehicles: mostly cars, some vans, trucks and buses.
VehicleKind drawKind(double u, double car, double van, double truck) {
  return u < car ? VehicleKind::kCar : u < car + van ? VehicleKind::kVan : u < car + van + truck ? VehicleKind::kTruck
                                                                                               : VehicleKind::kBus;
}

}  // namespace

void WorldConfig::validate() const {
  if (preset != "urban" && preset != "forest" && preset != "flat") {
    throw std::invalid_argument("preset must be urban, forest or flat, got '" + preset + "'");
  }
  if (!(route_length > 0) || !std::isfinite(route_length)) throw std::invalid_argument("route_length must be positive");
  if (!(speed > 0) || !std::isfinite(speed)) throw std::invalid_argument("speed must be positive");
  if (moving_vehicles < 0) throw std::invalid_argument("moving_vehicles must be >= 0");
  if (!(asphalt_grain >= 0 && asphalt_grain <= 1)) throw std::invalid_argument("asphalt_grain must be in [0, 1]");
  if (!(clouds >= 0 && clouds <= 1)) throw std::invalid_argument("clouds must be in [0, 1]");
}

void SensorModel::validate() const {
  auto check = [](bool ok, const char* what) {
    if (!ok) throw std::invalid_argument(what);
  };
  check(std::isfinite(gain) && gain > 0, "sensor gain must be positive");
  check(std::isfinite(offset) && std::abs(offset) < 255, "sensor offset must lie in (-255, 255) DN");
  check(std::isfinite(gamma) && gamma > 0, "sensor gamma must be positive");
  check(vignetting >= 0 && vignetting < 2.0 / 3.0, "sensor vignetting must lie in [0, 2/3)");
  check(blur_px >= 0 && blur_px <= 10, "sensor blur_px must lie in [0, 10]");
  check(read_noise >= 0 && read_noise <= 50, "sensor read_noise must lie in [0, 50] DN");
  check(shot_noise >= 0 && shot_noise <= 10, "sensor shot_noise must lie in [0, 10]");
}

Realism Realism::realistic() {
  Realism r;
  r.calib_rot_deg = 0.3;
  r.calib_trans_mm = 5.0;
  r.sensors.gain = 0.2;
  r.sensors.offset = 4.0;
  r.sensors.gamma = 0.1;
  r.sensors.base.vignetting = 0.45;
  r.sensors.base.read_noise = 2.0;
  r.sensors.base.shot_noise = 0.03;
  r.sensors.base.blur_px = 0.7;
  r.asphalt_grain = 0.08;
  r.clouds = 0.06;
  return r;
}

std::vector<SensorModel> drawSensors(const SensorSpread& spread, int cameras, uint64_t seed) {
  std::vector<SensorModel> out;
  for (int i = 0; i < cameras; ++i) {
    std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull + 7919u * static_cast<uint64_t>(i) + 1);
    std::uniform_real_distribution<double> U(-1.0, 1.0);
    SensorModel m = spread.base;
    m.gain *= 1.0 + spread.gain * U(rng);
    m.offset += spread.offset * U(rng);
    m.gamma *= 1.0 + spread.gamma * U(rng);
    m.validate();
    out.push_back(m);
  }
  return out;
}

std::vector<ExtrinsicError> drawExtrinsicErrors(int cameras, double rot_sigma_deg, double trans_sigma_mm,
                                                uint64_t seed) {
  if (!(rot_sigma_deg >= 0) || !(trans_sigma_mm >= 0)) throw std::invalid_argument("calibration error sigmas must be >= 0");
  std::vector<ExtrinsicError> out(std::max(cameras, 0));
  for (int i = 1; i < cameras; ++i) {
    std::mt19937_64 rng(seed * 0xD1B54A32D192ED03ull + 104729u * static_cast<uint64_t>(i) + 3);
    std::normal_distribution<double> N(0.0, 1.0);
    for (int a = 0; a < 3; ++a) out[i].rotation_deg[a] = rot_sigma_deg * N(rng);
    for (int a = 0; a < 3; ++a) out[i].translation_mm[a] = trans_sigma_mm * N(rng);
  }
  return out;
}

Rig perturbRig(const Rig& truth, const std::vector<ExtrinsicError>& errors) {
  if (errors.size() != truth.cameras.size()) throw std::invalid_argument("one calibration error per camera needed");
  Rig rig = truth;
  if (rig.cameras.empty()) return rig;
  const Eigen::Isometry3d T_base_cam0 = truth.cameras[0].T_base_cam * truth.cameras[0].T_cam0_cam.inverse();
  for (size_t i = 0; i < rig.cameras.size(); ++i) {
    const Eigen::Vector3d w = errors[i].rotation_deg * (M_PI / 180.0);
    Eigen::Isometry3d dT = Eigen::Isometry3d::Identity();
    if (w.norm() > 0) dT.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
    dT.translation() = errors[i].translation_mm * 1e-3;
    rig.cameras[i].T_cam0_cam = truth.cameras[i].T_cam0_cam * dT;
    rig.cameras[i].T_base_cam = T_base_cam0 * rig.cameras[i].T_cam0_cam;
  }
  return rig;
}

World::World(const WorldConfig& config) : config_(config) {
  config_.validate();
  buildRoute();
  build();
  indexGrid();
}

void World::buildRoute() {
  // A walk on the street grid from the origin, heading +x, turning at some
  // intersections (never back), long enough for the route length.
  std::mt19937 rng(config_.seed * 7919u + 17u);
  Eigen::Vector2i cell(0, 0), dir(1, 0);
  waypoints_ = {Eigen::Vector2d(0, 0)};
  double length = 0;
  int straight = 0;
  while (length < config_.route_length + 2 * kBlock) {
    cell += dir;
    ++straight;
    const Eigen::Vector2d p = cell.cast<double>() * kBlock;
    length += kBlock;
    const int roll = static_cast<int>(rng() % 6);
    if (straight >= 2 && roll < 2) {
      dir = roll == 0 ? Eigen::Vector2i(-dir.y(), dir.x()) : Eigen::Vector2i(dir.y(), -dir.x());
      waypoints_.push_back(p);
      straight = 0;
    }
  }
  waypoints_.push_back((cell + dir).cast<double>() * kBlock);
  cumulative_ = {0.0};
  for (size_t i = 1; i < waypoints_.size(); ++i) {
    cumulative_.push_back(cumulative_.back() + (waypoints_[i] - waypoints_[i - 1]).norm());
  }
}

// Point on the route at arc length s (corners rounded with kTurnRadius arcs,
// parametrised by the straight path's arc length, which differs by < 10 %).
Eigen::Vector3d World::routePoint(double s, Eigen::Vector2d* tangent) const {
  s = std::clamp(s, 0.0, cumulative_.back() - 1e-6);
  size_t i = std::upper_bound(cumulative_.begin(), cumulative_.end(), s) - cumulative_.begin() - 1;
  const Eigen::Vector2d a = waypoints_[i], b = waypoints_[i + 1];
  const Eigen::Vector2d dir = (b - a).normalized();
  const double along = s - cumulative_[i];
  Eigen::Vector2d p = a + along * dir;
  Eigen::Vector2d tan = dir;
  // Near a corner: blend onto a circular arc between the two segments.
  auto arc = [&](const Eigen::Vector2d& corner, const Eigen::Vector2d& in, const Eigen::Vector2d& out, double u) {
    // u in [0, 1] across the turn: quadratic Bezier with control point at the corner
    const Eigen::Vector2d p0 = corner - kTurnRadius * in, p2 = corner + kTurnRadius * out;
    p = (1 - u) * (1 - u) * p0 + 2 * u * (1 - u) * corner + u * u * p2;
    tan = (2 * (1 - u) * (corner - p0) + 2 * u * (p2 - corner)).normalized();
  };
  const double seg = cumulative_[i + 1] - cumulative_[i];
  if (i + 2 < waypoints_.size() && along > seg - kTurnRadius) {
    const Eigen::Vector2d out = (waypoints_[i + 2] - b).normalized();
    if (out.dot(dir) < 0.99) arc(b, dir, out, 0.5 * (along - (seg - kTurnRadius)) / kTurnRadius);
  } else if (i > 0 && along < kTurnRadius) {
    const Eigen::Vector2d in = (a - waypoints_[i - 1]).normalized();
    if (in.dot(dir) < 0.99) arc(a, in, dir, 0.5 + 0.5 * along / kTurnRadius);
  }
  if (tangent) *tangent = tan;
  return Eigen::Vector3d(p.x(), p.y(), 0.0);
}

Eigen::Isometry3d World::egoPose(double t) const {
  Eigen::Vector2d tan;
  // Ego drives in the right lane, 1.5 lanes right of the centreline.
  const Eigen::Vector3d c = routePoint(20.0 + config_.speed * t, &tan);
  const Eigen::Vector3d right(tan.y(), -tan.x(), 0.0);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(std::atan2(tan.y(), tan.x()), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = c + 1.5 * kLane * right;
  return T;
}

Eigen::Isometry3d World::vehiclePoseById(int id, double t) const {
  if (id < 0 || id >= numVehicleIds()) throw std::out_of_range("no vehicle with id " + std::to_string(id));
  return isMoving(id) ? vehiclePose(id, t) : parked_poses_[id - numVehicles()];
}

int World::addParkedVehicle(const VehicleDims& dims, const Eigen::Isometry3d& pose) {
  models_.emplace_back(dims);
  parked_poses_.push_back(pose);
  if (!cells_.empty()) indexGrid();  // after construction: index it now
  return numVehicleIds() - 1;
}

void World::addParkedRow(const Eigen::Vector2d& a, const Eigen::Vector2d& dir, const Eigen::Vector2d& left,
                         double len, std::mt19937& rng) {
  // Parked vehicles in the parking strip, most along the kerb, some angled
  // (up to 8 degrees, so they stay clear of the lane), facing either way.
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const double edge = kRoadHalfWidth + kSidewalk;
  for (double s = edge + 4 + 4 * U(rng); s < len - edge - 6;) {
    if (U(rng) < 0.35) {
      s += 3 + 6 * U(rng);
      continue;
    }
    const VehicleDims dims = drawVehicle(drawKind(U(rng), 0.68, 0.2, 0.08), rng);
    if (s + dims.length > len - edge - 2) break;
    const double angle = dims.length < 6 && U(rng) < 0.3 ? (U(rng) < 0.5 ? -1 : 1) * (4 + 4 * U(rng)) * M_PI / 180
                                                         : (U(rng) - 0.5) * 2 * M_PI / 180;
    // Wide vehicles stand with two wheels on the kerb, leaving the lane clear.
    const double half_lateral = 0.5 * (dims.length * std::abs(std::sin(angle)) + dims.width * std::cos(angle));
    const double outer = dims.width > 2.0 ? kRoadHalfWidth + 0.5 : kRoadHalfWidth - 0.1;
    const Eigen::Vector2d c = a + (s + 0.5 * dims.length) * dir + (outer - half_lateral) * left;
    const double heading = std::atan2(dir.y(), dir.x()) + (U(rng) < 0.5 ? M_PI : 0.0) + angle;
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(c.x(), c.y(), 0.0);
    addParkedVehicle(dims, T);
    s += dims.length + 0.8 + 2.5 * U(rng);
  }
}

Eigen::Isometry3d World::vehiclePose(int i, double t) const {
  const MovingVehicle& v = vehicles_[i];
  Eigen::Vector2d tan;
  const Eigen::Vector3d c = routePoint(v.s0 + v.speed * t, &tan);
  const Eigen::Vector3d left(-tan.y(), tan.x(), 0.0);
  const double heading = std::atan2(tan.y(), tan.x()) + (v.speed < 0 ? M_PI : 0.0);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = c + v.lateral * left;
  return T;
}

void World::addStreetSide(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& left,
                          uint64_t key) {
  // Furnishes the side of the street a -> b lying towards `left`.
  std::mt19937 rng(static_cast<uint32_t>(key * 2654435761u) ^ config_.seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const Eigen::Vector2d dir = (b - a).normalized();
  const double len = (b - a).norm();
  auto box2 = [&](double s0, double s1, double l0, double l1, double z0, double z1, Material m, float albedo) {
    const Eigen::Vector2d p0 = a + s0 * dir + l0 * left, p1 = a + s1 * dir + l1 * left;
    Box bx{Eigen::Vector3d(std::min(p0.x(), p1.x()), std::min(p0.y(), p1.y()), z0),
           Eigen::Vector3d(std::max(p0.x(), p1.x()), std::max(p0.y(), p1.y()), z1), m, albedo, -1};
    boxes_.push_back(bx);
  };
  const double edge = kRoadHalfWidth + kSidewalk;
  if (config_.preset == "urban") {
    // Facades: buildings of varied width, setback, height and material.
    for (double s = edge; s < len - edge;) {
      const double w = 8 + 12 * U(rng);
      const double s1 = std::min(s + w, len - edge);
      const double setback = 3.0 * U(rng) * U(rng);
      const bool brick = U(rng) < 0.55;
      box2(s, s1, edge + setback, edge + setback + 10 + 6 * U(rng), 0, 8 + 17 * U(rng), brick ? kBrick : kPlaster,
           brick ? 0.45f + 0.15f * U(rng) : 0.55f + 0.3f * U(rng));
      s = s1 + (U(rng) < 0.25 ? 2 + 4 * U(rng) : 0.0);
    }
    // Poles on the sidewalk, parked cars at the kerb.
    for (double s = edge + 5 + 10 * U(rng); s < len - edge; s += 22 + 10 * U(rng)) {
      box2(s, s + 0.18, kRoadHalfWidth + 0.6, kRoadHalfWidth + 0.78, 0, 5.5, kMetal, 0.35f);
    }
    // Street trees on the sidewalk.
    for (double s = edge + 12 + 10 * U(rng); s < len - edge - 3; s += 25 + 20 * U(rng)) {
      const double l = kRoadHalfWidth + 1.7, r = 1.2 + 0.6 * U(rng);
      box2(s, s + 0.3, l, l + 0.3, 0, 3.5, kBark, 0.32f);
      const Eigen::Vector2d c = a + (s + 0.15) * dir + (l + 0.15) * left;
      spheres_.push_back({Eigen::Vector3d(c.x(), c.y(), 3.3 + r), r, kFoliage, 0.6f + 0.2f * static_cast<float>(U(rng))});
    }
    addParkedRow(a, dir, left, len, rng);
  } else if (config_.preset == "forest") {
    for (double s = edge - 2; s < len - edge + 2; s += 3 + 5 * U(rng)) {
      const double l = kRoadHalfWidth + 2.0 + 12.0 * U(rng) * U(rng);
      const double h = 3 + 3 * U(rng), r = 1.8 + 1.8 * U(rng);
      box2(s, s + 0.45, l, l + 0.45, 0, h + 0.5 * r, kBark, 0.3f + 0.1f * static_cast<float>(U(rng)));
      const Eigen::Vector2d c = a + (s + 0.22) * dir + (l + 0.22) * left;
      spheres_.push_back({Eigen::Vector3d(c.x(), c.y(), h + r), r, kFoliage, 0.6f + 0.2f * static_cast<float>(U(rng))});
    }
  }
}

void World::build() {
  // Moving vehicles (ids 0 .., before the parked ones): half oncoming (left
  // lane, against the route), half overtaking (ego lane, faster than the ego,
  // starting behind it).
  std::mt19937 rng(config_.seed * 104729u + 3u);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  for (int i = 0; i < config_.moving_vehicles; ++i) {
    MovingVehicle v;
    const VehicleDims dims = drawVehicle(drawKind(U(rng), 0.55, 0.2, 0.12), rng);
    models_.emplace_back(dims);
    v.albedo = dims.paint;
    if (i % 2 == 0) {
      v.lateral = (i % 4 == 0 ? 0.5 : 1.5) * kLane;
      v.speed = -(6 + 6 * U(rng));
      v.s0 = 60 + (config_.route_length + 80) * (i / 2 + 0.5 + 0.3 * U(rng)) / std::max(1, (config_.moving_vehicles + 1) / 2);
    } else {
      v.lateral = -0.5 * kLane;  // inner lane: passes the ego on its left
      v.speed = config_.speed + 3 + 4 * U(rng);
      v.s0 = 20 - 15 - 40 * (i / 2) - 20 * U(rng);
    }
    vehicles_.push_back(v);
  }
  // Streets the route runs along, with both sides furnished, segment by segment
  // between intersections, plus the cross streets' corners.
  std::set<std::tuple<int, int, int, int>> done;
  for (size_t i = 0; i + 1 < waypoints_.size(); ++i) {
    const Eigen::Vector2d dir = (waypoints_[i + 1] - waypoints_[i]).normalized();
    const int n = static_cast<int>(std::round((waypoints_[i + 1] - waypoints_[i]).norm() / kBlock));
    for (int k = 0; k < n; ++k) {
      const Eigen::Vector2d a = waypoints_[i] + k * kBlock * dir, b = a + kBlock * dir;
      for (int side : {-1, 1}) {
        const Eigen::Vector2d left = side * Eigen::Vector2d(-dir.y(), dir.x());
        // The same street side seen from either direction is furnished once.
        const Eigen::Vector2d lo = a.cwiseMin(b), mid = 0.5 * (a + b) + left;
        const auto key = std::make_tuple(int(std::round(lo.x())), int(std::round(lo.y())),
                                         int(std::round(mid.x() * 2)), int(std::round(mid.y() * 2)));
        if (!done.insert(key).second) continue;
        const Eigen::Vector2d from = (left.x() * dir.y() - left.y() * dir.x()) < 0 ? a : b;
        const Eigen::Vector2d to = from == a ? b : a;
        addStreetSide(from, to, left, static_cast<uint64_t>(std::hash<double>()(mid.x() * 1e3 + mid.y())));
      }
    }
  }
}

void World::indexGrid() {
  Eigen::Vector2d lo(1e18, 1e18), hi(-1e18, -1e18);
  for (const auto& w : waypoints_) lo = lo.cwiseMin(w), hi = hi.cwiseMax(w);
  lo -= Eigen::Vector2d::Constant(kBlock), hi += Eigen::Vector2d::Constant(kBlock);
  grid_min_ = lo;
  grid_w_ = static_cast<int>(std::ceil((hi.x() - lo.x()) / cell_));
  grid_h_ = static_cast<int>(std::ceil((hi.y() - lo.y()) / cell_));
  cells_.assign(static_cast<size_t>(grid_w_) * grid_h_, {});
  auto add = [&](const Eigen::Vector3d& blo, const Eigen::Vector3d& bhi, int id) {
    const int x0 = std::max(0, int((blo.x() - grid_min_.x()) / cell_)), x1 = std::min(grid_w_ - 1, int((bhi.x() - grid_min_.x()) / cell_));
    const int y0 = std::max(0, int((blo.y() - grid_min_.y()) / cell_)), y1 = std::min(grid_h_ - 1, int((bhi.y() - grid_min_.y()) / cell_));
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) cells_[static_cast<size_t>(y) * grid_w_ + x].push_back(id);
  };
  for (size_t i = 0; i < boxes_.size(); ++i) add(boxes_[i].lo, boxes_[i].hi, static_cast<int>(i));
  for (size_t j = 0; j < parked_poses_.size(); ++j) {
    const Eigen::Vector3d r = Eigen::Vector3d::Constant(models_[numVehicles() + j].radius());
    const Eigen::Vector3d& c = parked_poses_[j].translation();
    add(c - r, c + r, static_cast<int>(boxes_.size() + j));
  }
  for (size_t i = 0; i < spheres_.size(); ++i) {
    const Eigen::Vector3d r = Eigen::Vector3d::Constant(spheres_[i].r);
    add(spheres_[i].c - r, spheres_[i].c + r, ~static_cast<int>(i));
  }
}

std::vector<Eigen::Isometry3d> World::vehiclePoses(double time) const {
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < numVehicles(); ++i) poses.push_back(vehiclePose(i, time));
  return poses;
}

int8_t World::occupancyAt(double x, double y, double obstacle_height, double vehicle_height) const {
  // Solids the column's sample points lie in (a ray cast from inside a box
  // would not see it), from the grid cell's list.
  const int ix = static_cast<int>(std::floor((x - grid_min_.x()) / cell_));
  const int iy = static_cast<int>(std::floor((y - grid_min_.y()) / cell_));
  const double lo = obstacle_height + 1e-3, hi = vehicle_height;
  if (ix >= 0 && iy >= 0 && ix < grid_w_ && iy < grid_h_) {
    for (int id : cells_[static_cast<size_t>(iy) * grid_w_ + ix]) {
      if (id >= static_cast<int>(boxes_.size())) {
        const int vid = numVehicles() + id - static_cast<int>(boxes_.size());
        const VehicleDims& dims = models_[vid].dims();
        const Eigen::Vector3d q = parked_poses_[vid - numVehicles()].inverse() * Eigen::Vector3d(x, y, 0.5 * (lo + hi));
        if (std::abs(q.x()) <= 0.5 * dims.length && std::abs(q.y()) <= 0.5 * dims.width &&
            obstacle_height < dims.height) {
          return 100;
        }
      } else if (id >= 0) {
        const Box& b = boxes_[id];
        if (x >= b.lo.x() && x <= b.hi.x() && y >= b.lo.y() && y <= b.hi.y() && b.hi.z() > lo && b.lo.z() < hi) {
          return 100;
        }
      } else {
        const Sphere& sp = spheres_[~id];
        const double r2 = sp.r * sp.r - (x - sp.c.x()) * (x - sp.c.x()) - (y - sp.c.y()) * (y - sp.c.y());
        if (r2 >= 0 && sp.c.z() + std::sqrt(r2) > lo && sp.c.z() - std::sqrt(r2) < hi) return 100;
      }
    }
  }
  // Then the first surface under vehicle_height: the ground, or a low solid
  // (a kerb) under obstacle_height.
  const Hit down = cast(Eigen::Vector3d(x, y, hi), -Eigen::Vector3d::UnitZ(), std::vector<Eigen::Isometry3d>(),
                        hi + 1.0);
  if (!(down.t < hi + 1.0)) return -1;
  return hi - down.t > obstacle_height ? 100 : 0;
}

Hit World::cast(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double time, double max_range) const {
  return cast(o, d, vehiclePoses(time), max_range);
}

Hit World::cast(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const std::vector<Eigen::Isometry3d>& vehicles,
                double max_range) const {
  Hit best;
  best.t = max_range;
  // Ground.
  if (d.z() < -1e-9 && o.z() > 0) {
    const double t = -o.z() / d.z();
    if (t < best.t) best.t = t, best.n = Eigen::Vector3d::UnitZ(), best.material = kAsphalt, best.albedo = 1.0f;
  }
  // Static objects: walk the grid cells along the ray's x-y projection.
  const Eigen::Vector2d d2(d.x(), d.y());
  const double len2 = d2.norm();
  double cx = (o.x() - grid_min_.x()) / cell_, cy = (o.y() - grid_min_.y()) / cell_;
  int ix = static_cast<int>(std::floor(cx)), iy = static_cast<int>(std::floor(cy));
  const int step_x = d.x() > 0 ? 1 : -1, step_y = d.y() > 0 ? 1 : -1;
  const double inv_x = std::abs(d.x()) > 1e-12 ? cell_ / std::abs(d.x()) : 1e30;
  const double inv_y = std::abs(d.y()) > 1e-12 ? cell_ / std::abs(d.y()) : 1e30;
  double next_x = (d.x() > 0 ? (ix + 1 - cx) : (cx - ix)) * inv_x;
  double next_y = (d.y() > 0 ? (iy + 1 - cy) : (cy - iy)) * inv_y;
  double t_cell = 0;
  const int max_steps = len2 > 1e-9 ? grid_w_ + grid_h_ : 1;
  for (int step = 0; step < max_steps && t_cell < best.t; ++step) {
    if (ix >= 0 && iy >= 0 && ix < grid_w_ && iy < grid_h_) {
      for (int id : cells_[static_cast<size_t>(iy) * grid_w_ + ix]) {
        double t;
        Eigen::Vector3d n;
        if (id >= static_cast<int>(boxes_.size())) {
          const int vid = numVehicles() + id - static_cast<int>(boxes_.size());
          castVehicle(vid, parked_poses_[vid - numVehicles()], o, d, &best);
        } else if (id >= 0) {
          const Box& b = boxes_[id];
          if (rayBox(o, d, b.lo, b.hi, &t, &n) && t < best.t) {
            best.t = t, best.n = n, best.material = b.material, best.albedo = b.albedo, best.object = -1;
          }
        } else {
          const Sphere& s = spheres_[~id];
          const Eigen::Vector3d oc = o - s.c;
          const double b = oc.dot(d), c = oc.squaredNorm() - s.r * s.r, disc = b * b - c;
          if (disc >= 0) {
            t = -b - std::sqrt(disc);
            if (t > 1e-6 && t < best.t) {
              best.t = t, best.n = (o + t * d - s.c) / s.r, best.material = s.material, best.albedo = s.albedo;
              best.object = -1;
            }
          }
        }
      }
    } else if ((ix < 0 && step_x < 0) || (iy < 0 && step_y < 0) || (ix >= grid_w_ && step_x > 0) ||
               (iy >= grid_h_ && step_y > 0)) {
      break;  // left the grid for good
    }
    if (len2 <= 1e-9) break;
    if (next_x < next_y) {
      t_cell = next_x, next_x += inv_x, ix += step_x;
    } else {
      t_cell = next_y, next_y += inv_y, iy += step_y;
    }
  }
  for (int i = 0; i < static_cast<int>(vehicles.size()); ++i) castVehicle(i, vehicles[i], o, d, &best);
  if (best.t >= max_range) return Hit();
  if (best.material == kAsphalt) best.albedo = groundShadow(o + best.t * d, vehicles);
  return best;
}

bool World::castVehicle(int id, const Eigen::Isometry3d& T_W_V, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                        Hit* best) const {
  const VehicleModel& model = models_[id];
  // Bounding sphere first: most rays pass far from most vehicles.
  const Eigen::Vector3d oc = T_W_V.translation() - o;
  const double along = oc.dot(d), r = model.radius();
  if (along + r < 0 || along - r > best->t || oc.squaredNorm() - along * along > r * r) return false;
  const Eigen::Vector3d ol = T_W_V.inverse() * o, dl = T_W_V.linear().transpose() * d;
  VehicleModel::LocalHit h;
  if (!model.intersect(ol, dl, best->t, &h)) return false;
  best->t = h.t, best->n = T_W_V.linear() * h.n, best->material = h.material, best->albedo = h.albedo;
  best->object = id;
  return true;
}

float World::groundShadow(const Eigen::Vector3d& p, const std::vector<Eigen::Isometry3d>& vehicles) const {
  // Ambient occlusion under a vehicle: dark under the body, fading over 0.4 m
  // beyond the footprint.
  float factor = 1.0f;
  auto under = [&](int id, const Eigen::Isometry3d& T) {
    const VehicleModel& m = models_[id];
    if ((T.translation() - p).squaredNorm() > m.radius() * m.radius()) return;
    const Eigen::Vector3d q = T.inverse() * p;
    const double out = std::max(std::abs(q.x()) - 0.5 * m.dims().length, std::abs(q.y()) - 0.5 * m.dims().width);
    const double dark = std::clamp(0.5 - out / 0.4, 0.0, 1.0);  // 1 well inside, 0 beyond 0.2 m outside
    factor = std::min(factor, static_cast<float>(1.0 - 0.7 * dark));
  };
  for (int i = 0; i < static_cast<int>(vehicles.size()); ++i) under(i, vehicles[i]);
  const int ix = static_cast<int>(std::floor((p.x() - grid_min_.x()) / cell_));
  const int iy = static_cast<int>(std::floor((p.y() - grid_min_.y()) / cell_));
  if (ix >= 0 && iy >= 0 && ix < grid_w_ && iy < grid_h_) {
    for (int id : cells_[static_cast<size_t>(iy) * grid_w_ + ix]) {
      if (id < static_cast<int>(boxes_.size())) continue;
      const int vid = numVehicles() + id - static_cast<int>(boxes_.size());
      under(vid, parked_poses_[vid - numVehicles()]);
    }
  }
  return factor;
}

float World::shade(const Hit& h, const Eigen::Vector3d& p) const {
  const uint32_t seed = config_.seed * 31u;
  float albedo = h.albedo;
  switch (h.material) {
    case kAsphalt: {
      // Ground: road, markings, kerb, sidewalk or grass, by the distance to the
      // nearest street centreline.
      const double dx = std::abs(p.x() - std::round(p.x() / kBlock) * kBlock);
      const double dy = std::abs(p.y() - std::round(p.y() / kBlock) * kBlock);
      const double dist = std::min(dx, dy), along = dy < dx ? p.x() : p.y();
      const bool crossing = dx < kRoadHalfWidth && dy < kRoadHalfWidth;
      if (dist < kRoadHalfWidth) {
        albedo = 0.28f + 0.16f * fbm(p * 9.0, seed) + 0.05f * noise(p * 40.0, seed + 5);
        if (config_.asphalt_grain > 0) {  // grain: 2.5 cm and 1.1 cm value noise
          albedo += static_cast<float>(config_.asphalt_grain) *
                    (0.6f * noise(p * 40.0, seed + 14) + 0.4f * noise(p * 90.0, seed + 15) - 0.5f);
        }
        const bool centre = dist < 0.08;
        const bool lane_line = std::abs(dist - kLane) < 0.075 && std::fmod(std::abs(along), 6.0) < 3.0;
        const bool edge_line = dist > 2 * kLane - 0.05 && dist < 2 * kLane + 0.1;
        if (!crossing && (centre || lane_line || edge_line)) albedo = 0.85f;
        albedo *= h.albedo;  // shadow under vehicles
      } else if (config_.preset == "urban" && dist < kRoadHalfWidth + 0.3) {
        albedo = (0.62f + 0.05f * noise(p * 10.0, seed + 6)) * h.albedo;
      } else if (config_.preset == "urban" && dist < kRoadHalfWidth + kSidewalk) {
        const bool joint = std::fmod(std::abs(along), 0.6) < 0.03 || std::fmod(dist, 0.6) < 0.03;
        albedo = joint ? 0.35f : 0.55f + 0.1f * fbm(p * 5.0, seed + 7);
      } else {
        albedo = 0.5f + 0.25f * fbm(p * 3.0, seed + 8);  // grass, bright in near infrared
      }
      break;
    }
    case kBrick:
    case kPlaster: {
      const double u = std::abs(h.n.x()) > 0.5 ? p.y() : p.x();
      const bool window = std::fmod(p.z(), 3.0) > 1.0 && std::fmod(p.z(), 3.0) < 2.4 &&
                          std::fmod(std::abs(u), 3.5) > 1.0 && std::fmod(std::abs(u), 3.5) < 2.6 && p.z() > 1.0 &&
                          std::abs(h.n.z()) < 0.5;
      if (window) {
        albedo = 0.12f + 0.05f * noise(p * 2.0, seed + 9);
      } else if (h.material == kBrick) {
        const double row = std::floor(p.z() / 0.3);
        const bool mortar = std::fmod(p.z(), 0.3) < 0.035 || std::fmod(std::abs(u) + 0.3 * std::fmod(row, 2.0), 0.6) < 0.035;
        albedo = mortar ? 0.7f : h.albedo + 0.12f * (hash3(int(std::floor(std::abs(u) / 0.6)), int(row), 0, seed) - 0.5f) +
                                   0.06f * noise(p * 6.0, seed + 10);
      } else {
        albedo = h.albedo + 0.015f * noise(p * 1.5, seed + 11);  // plain wall: little texture
      }
      break;
    }
    case kFoliage:
      albedo = h.albedo + 0.3f * (fbm(p * 4.0, seed + 12) - 0.5f);
      break;
    case kBark:
      albedo = h.albedo + 0.15f * (noise(Eigen::Vector3d(p.x() * 8, p.y() * 8, p.z() * 1.5), seed + 13) - 0.5f);
      break;
    case kCarPaint:  // faint dirt and sheen: more texture than the glass, less than a wall
      albedo = h.albedo * (0.97f + 0.06f * noise(p * 3.0, seed + 16));
      break;
    default:
      break;
  }
  if (h.material == kLight) return h.albedo;  // lamps shine whatever the sun
  static const Eigen::Vector3d sun = Eigen::Vector3d(0.45, 0.3, 0.84).normalized();
  const double lambert = std::max(0.0, h.n.dot(sun));
  return static_cast<float>(std::clamp(albedo, 0.0f, 1.0f) * (0.45 + 0.55 * lambert));
}

World::Frame World::render(const CameraModel& camera, const std::vector<Eigen::Vector3f>& rays,
                           const Eigen::Isometry3d& T_W_C, double time, uint64_t noise_seed,
                           const SensorModel& sensor) const {
  const int w = camera.width(), h = camera.height();
  if (rays.size() != static_cast<size_t>(w) * h) throw std::invalid_argument("ray table does not match the camera");
  sensor.validate();
  Frame f;
  f.image.create(h, w, CV_8UC1);
  cv::Mat radiance(h, w, CV_32FC1);  // after vignetting, before the sensor
  const float vignetting = static_cast<float>(sensor.vignetting);
  const float vignetting_floor = 1.0f - 1.5f * vignetting;
  f.depth.create(h, w, CV_32FC1);
  f.ids.create(h, w, CV_16SC1);
  f.materials.create(h, w, CV_8UC1);
  const Eigen::Vector3d o = T_W_C.translation();
  const Eigen::Matrix3d R = T_W_C.linear();
  const std::vector<Eigen::Isometry3d> vehicles = vehiclePoses(time);
#pragma omp parallel for schedule(dynamic, 4)
  for (int v = 0; v < h; ++v) {
    float* img = radiance.ptr<float>(v);
    float* dep = f.depth.ptr<float>(v);
    int16_t* ids = f.ids.ptr<int16_t>(v);
    uint8_t* mat = f.materials.ptr<uint8_t>(v);
    for (int u = 0; u < w; ++u) {
      const Eigen::Vector3f& rc = rays[static_cast<size_t>(v) * w + u];
      float intensity = 0.0f;
      dep[u] = NAN;
      ids[u] = -1;
      mat[u] = kSky;
      if (rc.z() == rc.z()) {
        const Eigen::Vector3d d = R * rc.cast<double>();
        const Hit hit = cast(o, d, vehicles);
        if (std::isfinite(hit.t) && hit.material != kSky) {
          intensity = shade(hit, o + hit.t * d);
          dep[u] = static_cast<float>(hit.t);
          ids[u] = static_cast<int16_t>(hit.object);
          mat[u] = hit.material;
        } else {
          intensity = 0.88f + 0.06f * static_cast<float>(std::max(0.0, d.z()));  // plain sky
          if (config_.clouds > 0) {  // clouds: a texture on the directions, at infinity
            const uint32_t seed = config_.seed * 31u + 17u;
            intensity += static_cast<float>(config_.clouds) *
                         ((config_.overcast ? overcastClouds(d, seed) : fbm(d * 3.0, seed)) - 0.5f);
          }
        }
        // Vignetting: darker towards the edge of the field of view.
        const float off_axis = std::acos(std::clamp(rc.z(), -1.0f, 1.0f)) / static_cast<float>(M_PI_2);
        intensity *= std::max(vignetting_floor, 1.0f - vignetting * off_axis * off_axis);
      }
      img[u] = intensity;
    }
  }
  if (sensor.blur_px > 0) cv::GaussianBlur(radiance, radiance, cv::Size(), sensor.blur_px, sensor.blur_px, cv::BORDER_REPLICATE);
  const bool linear = sensor.gain == 1.0 && sensor.gamma == 1.0;
  const float gain = static_cast<float>(sensor.gain), gamma = static_cast<float>(sensor.gamma);
  const float offset = static_cast<float>(sensor.offset), shot = static_cast<float>(sensor.shot_noise);
#pragma omp parallel for schedule(static)
  for (int v = 0; v < h; ++v) {
    std::mt19937_64 rng(noise_seed * 1000003ull + static_cast<uint64_t>(v));
    std::normal_distribution<float> gauss(0.0f, 1.0f);
    const float* in = radiance.ptr<float>(v);
    uint8_t* img = f.image.ptr<uint8_t>(v);
    for (int u = 0; u < w; ++u) {
      float dn = linear ? 255.0f * in[u] : 255.0f * std::pow(std::clamp(gain * in[u], 0.0f, 1.0f), gamma);
      dn += offset;
      const float sigma = shot > 0 ? std::sqrt(static_cast<float>(sensor.read_noise * sensor.read_noise) +
                                               shot * std::max(dn, 0.0f))
                                   : static_cast<float>(sensor.read_noise);
      img[u] = static_cast<uint8_t>(std::clamp(dn + sigma * gauss(rng), 0.0f, 255.0f));
    }
  }
  return f;
}

void World::saveStaticMeshPly(const std::string& path) const {
  pcl::PointCloud<pcl::PointXYZ> vertices;
  pcl::PolygonMesh mesh;
  auto tri = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    pcl::Vertices t;
    for (const Eigen::Vector3d* p : {&a, &b, &c}) {
      t.vertices.push_back(static_cast<std::uint32_t>(vertices.size()));
      vertices.push_back(pcl::PointXYZ(p->x(), p->y(), p->z()));
    }
    mesh.polygons.push_back(t);
  };
  auto quad = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
    tri(a, b, c);
    tri(a, c, d);
  };
  // Ground, in 10 m tiles so the mesh can be sampled evenly.
  const double x0 = grid_min_.x(), y0 = grid_min_.y(), x1 = x0 + grid_w_ * cell_, y1 = y0 + grid_h_ * cell_;
  for (double x = x0; x < x1; x += 10)
    for (double y = y0; y < y1; y += 10)
      quad({x, y, 0}, {x + 10, y, 0}, {x + 10, y + 10, 0}, {x, y + 10, 0});
  for (const Box& b : boxes_) {
    const Eigen::Vector3d& l = b.lo;
    const Eigen::Vector3d& h = b.hi;
    quad({l.x(), l.y(), l.z()}, {h.x(), l.y(), l.z()}, {h.x(), l.y(), h.z()}, {l.x(), l.y(), h.z()});
    quad({l.x(), h.y(), l.z()}, {l.x(), h.y(), h.z()}, {h.x(), h.y(), h.z()}, {h.x(), h.y(), l.z()});
    quad({l.x(), l.y(), l.z()}, {l.x(), l.y(), h.z()}, {l.x(), h.y(), h.z()}, {l.x(), h.y(), l.z()});
    quad({h.x(), l.y(), l.z()}, {h.x(), h.y(), l.z()}, {h.x(), h.y(), h.z()}, {h.x(), l.y(), h.z()});
    quad({l.x(), l.y(), h.z()}, {h.x(), l.y(), h.z()}, {h.x(), h.y(), h.z()}, {l.x(), h.y(), h.z()});
  }
  for (size_t j = 0; j < parked_poses_.size(); ++j) {
    const Eigen::Isometry3d& T = parked_poses_[j];
    for (const auto& t : models_[numVehicles() + j].triangles()) tri(T * t[0], T * t[1], T * t[2]);
  }
  for (const Sphere& s : spheres_) {
    const int nu = 16, nv = 8;
    auto P = [&](int i, int j) {
      const double th = M_PI * j / nv, ph = 2 * M_PI * i / nu;
      return Eigen::Vector3d(s.c + s.r * Eigen::Vector3d(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th)));
    };
    for (int i = 0; i < nu; ++i)
      for (int j = 0; j < nv; ++j) quad(P(i, j), P(i + 1, j), P(i + 1, j + 1), P(i, j + 1));
  }
  pcl::toPCLPointCloud2(vertices, mesh.cloud);
  // PCL writes into memory, the file goes through the checked writer.
  writeFileSafely(path, captureFileOutput([&](const std::string& name) {
                    if (pcl::io::savePLYFileBinary(name, mesh) != 0) {
                      throw std::runtime_error(path + ": cannot write PLY mesh");
                    }
                  }));
}

}  // namespace synth
}  // namespace fisheye_mapping
