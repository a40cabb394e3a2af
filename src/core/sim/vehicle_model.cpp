#include "fisheye_mapping/core/sim/vehicle_model.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace fisheye_mapping {
namespace synth {
namespace {

// Roles of the convex parts: which appearance rules apply to their faces.
enum Role { kLowerBody = 0, kGreenhouse, kTruckCab, kCargo, kChassis, kBusBody };

bool rayAabb(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
             double t_max) {
  double t0 = 0, t1 = t_max;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-12) {
      if (o[a] < lo[a] || o[a] > hi[a]) return false;
      continue;
    }
    double ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta), t1 = std::min(t1, tb);
    if (t0 > t1) return false;
  }
  return true;
}

double uniform(std::mt19937& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

}  // namespace

const char* kindName(VehicleKind kind) {
  static const char* names[] = {"car", "van", "truck", "bus"};
  return names[static_cast<int>(kind)];
}

const char* cocoName(VehicleKind kind) {
  static const char* names[] = {"car", "car", "truck", "bus"};
  return names[static_cast<int>(kind)];
}

int cocoId(VehicleKind kind) {
  static const int ids[] = {2, 2, 7, 5};
  return ids[static_cast<int>(kind)];
}

VehicleDims drawVehicle(VehicleKind kind, std::mt19937& rng) {
  VehicleDims v;
  v.kind = kind;
  switch (kind) {
    case VehicleKind::kCar:
      v.length = uniform(rng, 4.2, 4.8), v.width = uniform(rng, 1.75, 1.9), v.height = uniform(rng, 1.4, 1.55);
      break;
    case VehicleKind::kVan:
      v.length = uniform(rng, 4.8, 5.6), v.width = uniform(rng, 1.9, 2.05), v.height = uniform(rng, 1.9, 2.3);
      break;
    case VehicleKind::kTruck:
      v.length = uniform(rng, 7.0, 10.0), v.width = uniform(rng, 2.4, 2.55), v.height = uniform(rng, 3.2, 3.8);
      break;
    case VehicleKind::kBus:
      v.length = uniform(rng, 11.0, 12.0), v.width = uniform(rng, 2.5, 2.55), v.height = uniform(rng, 3.0, 3.3);
      break;
  }
  // Grey levels of real paints (white, silver, grey, dark) under a near-infrared camera.
  static const float levels[] = {0.85f, 0.68f, 0.5f, 0.3f};
  v.paint = levels[rng() % 4] + static_cast<float>(uniform(rng, -0.06, 0.06));
  v.paint2 = static_cast<float>(uniform(rng, 0.55, 0.92));
  return v;
}

VehicleModel::Convex VehicleModel::box(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, int role) {
  Convex c;
  for (int a = 0; a < 3; ++a) {
    Eigen::Vector4d p = Eigen::Vector4d::Zero();
    p[a] = 1, p[3] = hi[a];
    c.planes.push_back(p);
    p[a] = -1, p[3] = -lo[a];
    c.planes.push_back(p);
  }
  c.lo = lo, c.hi = hi, c.role = role;
  return c;
}

void VehicleModel::cut(Convex* c, const Eigen::Vector3d& n_in, const Eigen::Vector3d& p) {
  Eigen::Vector3d n = n_in.normalized();
  if (n.dot(0.5 * (c->lo + c->hi) - p) > 0) n = -n;  // outward: away from the part's centre
  c->planes.push_back(Eigen::Vector4d(n.x(), n.y(), n.z(), n.dot(p)));
}

namespace {
// Normal of the plane through the line p0 -> p1 in the (a, b) coordinate plane,
// containing the third axis.
Eigen::Vector3d lineNormal(int a, int b, const Eigen::Vector2d& p0, const Eigen::Vector2d& p1) {
  const Eigen::Vector2d t = p1 - p0;
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  n[a] = -t.y(), n[b] = t.x();
  return n;
}
Eigen::Vector3d at(int a, int b, const Eigen::Vector2d& p) {
  Eigen::Vector3d q = Eigen::Vector3d::Zero();
  q[a] = p.x(), q[b] = p.y();
  return q;
}
}  // namespace

#define CUT(part, a, b, x0, y0, x1, y1) \
  cut(&(part), lineNormal(a, b, {x0, y0}, {x1, y1}), at(a, b, {x0, y0}))

VehicleModel::VehicleModel(const VehicleDims& dims) : dims_(dims) {
  if (!(dims.length > 1 && dims.width > 0.5 && dims.height > 0.8 && dims.length < 30 && dims.width < 5 && dims.height < 6))
    throw std::invalid_argument("vehicle dimensions out of range");
  switch (dims.kind) {
    case VehicleKind::kCar: buildCar(); break;
    case VehicleKind::kVan: buildVan(); break;
    case VehicleKind::kTruck: buildTruck(); break;
    case VehicleKind::kBus: buildBus(); break;
  }
  lo_ = Eigen::Vector3d::Constant(1e9), hi_ = -lo_;
  for (const Convex& c : parts_) lo_ = lo_.cwiseMin(c.lo), hi_ = hi_.cwiseMax(c.hi);
  for (const Wheel& w : wheels_) {
    const Eigen::Vector3d e(w.r, w.half_w, w.r);
    lo_ = lo_.cwiseMin(w.c - e), hi_ = hi_.cwiseMax(w.c + e);
  }
  radius_ = std::sqrt(std::pow(std::max(-lo_.x(), hi_.x()), 2) + std::pow(std::max(-lo_.y(), hi_.y()), 2) +
                      std::pow(std::max(-lo_.z(), hi_.z()), 2));
}

void VehicleModel::addWheels(const std::vector<double>& axles_x, double r) {
  wheel_r_ = r;
  const double hw = 0.08 + 0.14 * r;
  for (double x : axles_x)
    for (double s : {-1.0, 1.0}) wheels_.push_back({Eigen::Vector3d(x, s * (0.5 * dims_.width + 0.015 - hw), r), r, hw, s});
}

void VehicleModel::buildCar() {
  const double L = dims_.length / 2, W = dims_.width / 2, H = dims_.height;
  clearance_ = 0.2, belt_ = 0.56 * H + 0.07, light_z_ = belt_ - 0.2, bumper_top_ = clearance_ + 0.25;
  Convex low = box({-L, -W, clearance_}, {L, W, belt_}, kLowerBody);
  CUT(low, 0, 2, L, belt_ - 0.16, L - 1.1, belt_);               // bonnet slopes to the front
  CUT(low, 0, 2, L, clearance_ + 0.18, L - 0.3, clearance_);     // front bumper's underside
  CUT(low, 0, 2, -L, belt_ - 0.07, -L + 0.35, belt_);            // boot lid
  CUT(low, 0, 2, -L, clearance_ + 0.2, -L + 0.35, clearance_);
  for (double s : {-1.0, 1.0}) {                                  // rounded corners in plan
    CUT(low, 0, 1, L, s * (W - 0.3), L - 0.45, s * W);
    CUT(low, 0, 1, -L, s * (W - 0.22), -L + 0.3, s * W);
  }
  windscreen_x0_ = L - 1.2, windscreen_x1_ = windscreen_x0_ - 0.8;
  rear_x0_ = -L + 0.75, rear_x1_ = rear_x0_ + 0.55;
  Convex cab = box({rear_x0_, -(W - 0.05), belt_ - 0.02}, {windscreen_x0_, W - 0.05, H}, kGreenhouse);
  CUT(cab, 0, 2, windscreen_x0_, belt_, windscreen_x1_, H);
  CUT(cab, 0, 2, rear_x0_, belt_, rear_x1_, H);
  for (double s : {-1.0, 1.0}) CUT(cab, 1, 2, s * (W - 0.05), belt_, s * (W - 0.22), H);  // tumblehome
  parts_ = {low, cab};
  addWheels({L - 0.85, -L + 0.95}, 0.31);
}

void VehicleModel::buildVan() {
  const double L = dims_.length / 2, W = dims_.width / 2, H = dims_.height;
  clearance_ = 0.22, belt_ = 1.0, light_z_ = belt_ - 0.22, bumper_top_ = clearance_ + 0.28;
  Convex low = box({-L, -W, clearance_}, {L, W, belt_}, kLowerBody);
  CUT(low, 0, 2, L, belt_ - 0.2, L - 0.55, belt_);
  CUT(low, 0, 2, L, clearance_ + 0.2, L - 0.25, clearance_);
  for (double s : {-1.0, 1.0}) {
    CUT(low, 0, 1, L, s * (W - 0.25), L - 0.35, s * W);
    CUT(low, 0, 1, -L, s * (W - 0.08), -L + 0.08, s * W);
  }
  windscreen_x0_ = L - 0.55, windscreen_x1_ = L - 1.25;
  rear_x0_ = rear_x1_ = -L;
  Convex cab = box({-L, -(W - 0.03), belt_ - 0.02}, {windscreen_x0_, W - 0.03, H}, kGreenhouse);
  CUT(cab, 0, 2, windscreen_x0_, belt_, windscreen_x1_, H);
  CUT(cab, 0, 2, -L, H - 0.12, -L + 0.12, H);
  for (double s : {-1.0, 1.0}) CUT(cab, 1, 2, s * (W - 0.03), belt_, s * (W - 0.1), H);
  parts_ = {low, cab};
  addWheels({L - 0.9, -L + 1.05}, 0.33);
}

void VehicleModel::buildTruck() {
  const double L = dims_.length / 2, W = dims_.width / 2, H = dims_.height;
  const double cab_h = std::min(H - 0.2, 3.0), cab_back = L - 2.1;
  clearance_ = 0.45, belt_ = 1.75, light_z_ = 0.85, bumper_top_ = 0.75;
  windscreen_x0_ = cab_back, windscreen_x1_ = cab_h;  // the truck keeps the cab's extent here
  Convex cab = box({cab_back, -W, clearance_}, {L, W, cab_h}, kTruckCab);
  CUT(cab, 0, 2, L, 1.6, L - 0.2, cab_h);                         // windscreen leans back
  CUT(cab, 0, 2, L - 0.1, cab_h - 0.12, L - 0.4, cab_h);
  for (double s : {-1.0, 1.0}) CUT(cab, 0, 1, L, s * (W - 0.15), L - 0.15, s * W);
  const Convex cargo = box({-L, -W, 1.1}, {cab_back - 0.15, W, H}, kCargo);
  const Convex chassis = box({-L + 0.3, -(W - 0.3), 0.6}, {cab_back, W - 0.3, 1.1}, kChassis);
  const Convex bar = box({-L + 0.05, -(W - 0.08), 0.5}, {-L + 0.3, W - 0.08, 0.78}, kChassis);
  parts_ = {cab, cargo, chassis, bar};
  std::vector<double> axles = {L - 1.25, -L + 1.7};
  if (dims_.length > 8.5) axles.push_back(-L + 3.0);
  addWheels(axles, 0.5);
}

void VehicleModel::buildBus() {
  const double L = dims_.length / 2, W = dims_.width / 2, H = dims_.height;
  clearance_ = 0.3, belt_ = 0.95, light_z_ = 0.7, bumper_top_ = clearance_ + 0.3;
  Convex body = box({-L, -W, clearance_}, {L, W, H}, kBusBody);
  CUT(body, 0, 2, L, H - 0.25, L - 0.25, H);
  CUT(body, 0, 2, -L, H - 0.2, -L + 0.2, H);
  CUT(body, 0, 2, L, clearance_ + 0.2, L - 0.12, clearance_);
  for (double s : {-1.0, 1.0}) {
    CUT(body, 0, 1, L, s * (W - 0.25), L - 0.25, s * W);
    CUT(body, 0, 1, -L, s * (W - 0.2), -L + 0.2, s * W);
  }
  parts_ = {body};
  addWheels({L - 2.7, -L + 3.3}, 0.5);
}

#undef CUT

std::vector<Eigen::Vector3d> VehicleModel::wheelCentres() const {
  std::vector<Eigen::Vector3d> out;
  for (const Wheel& w : wheels_) out.push_back(w.c + Eigen::Vector3d(0, w.outer_sign * w.half_w, 0));
  return out;
}

bool VehicleModel::intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_max, LocalHit* hit) const {
  if (!rayAabb(o, d, lo_, hi_, t_max)) return false;
  double best = t_max;
  int best_part = -1, best_face = -1;
  Eigen::Vector3d best_n;
  for (size_t k = 0; k < parts_.size(); ++k) {
    const Convex& c = parts_[k];
    double t0 = 1e-6, t1 = best;
    int face = -1;
    bool miss = false;
    for (size_t i = 0; i < c.planes.size() && !miss; ++i) {
      const Eigen::Vector4d& pl = c.planes[i];
      const double denom = pl.head<3>().dot(d), num = pl[3] - pl.head<3>().dot(o);
      if (std::abs(denom) < 1e-12) {
        miss = num < 0;
        continue;
      }
      const double t = num / denom;
      if (denom < 0) {
        if (t > t0) t0 = t, face = static_cast<int>(i);
      } else {
        t1 = std::min(t1, t);
      }
      miss = t0 > t1;
    }
    if (miss || face < 0) continue;  // no hit, or the origin inside
    best = t0, best_part = static_cast<int>(k), best_face = face, best_n = c.planes[face].head<3>();
  }
  // Wheels: tread (cylinder about y) and the two flat faces.
  int best_wheel = -1;
  bool on_face = false;
  for (size_t k = 0; k < wheels_.size(); ++k) {
    const Wheel& w = wheels_[k];
    const double ox = o.x() - w.c.x(), oz = o.z() - w.c.z();
    const double a = d.x() * d.x() + d.z() * d.z(), b = ox * d.x() + oz * d.z(), cc = ox * ox + oz * oz - w.r * w.r;
    if (a > 1e-12 && b * b - a * cc >= 0) {
      const double t = (-b - std::sqrt(b * b - a * cc)) / a;
      if (t > 1e-6 && t < best && std::abs(o.y() + t * d.y() - w.c.y()) <= w.half_w) {
        best = t, best_wheel = static_cast<int>(k), on_face = false, best_part = -1;
        best_n = Eigen::Vector3d(ox + t * d.x(), 0, oz + t * d.z()) / w.r;
      }
    }
    if (std::abs(d.y()) > 1e-12) {
      for (double s : {-1.0, 1.0}) {
        const double t = (w.c.y() + s * w.half_w - o.y()) / d.y();
        if (t <= 1e-6 || t >= best || s * d.y() > 0) continue;
        const double px = o.x() + t * d.x() - w.c.x(), pz = o.z() + t * d.z() - w.c.z();
        if (px * px + pz * pz > w.r * w.r) continue;
        best = t, best_wheel = static_cast<int>(k), on_face = true, best_part = -1;
        best_n = Eigen::Vector3d(0, s, 0);
      }
    }
  }
  if (best_part < 0 && best_wheel < 0) return false;
  hit->t = best;
  hit->n = best_n;
  const Eigen::Vector3d p = o + best * d;
  if (best_part >= 0) {
    hit->material = surface(parts_[best_part].role, best_face, p, best_n, d, &hit->albedo);
    return true;
  }
  const Wheel& w = wheels_[best_wheel];
  const double rho = std::hypot(p.x() - w.c.x(), p.z() - w.c.z()) / w.r;
  const bool outer = on_face && best_n.y() * w.outer_sign > 0;
  if (outer && rho < 0.62) {
    // Hub and rim: light metal with five dark openings between the spokes.
    const double angle = std::atan2(p.z() - w.c.z(), p.x() - w.c.x());
    const bool opening = rho > 0.28 && rho < 0.55 && std::fmod(angle / (2 * M_PI) * 5 + 5.25, 1.0) < 0.45;
    hit->material = kHub;
    hit->albedo = opening ? 0.12f : rho < 0.12 ? 0.35f : 0.6f;
  } else {
    hit->material = kTyre;
    hit->albedo = 0.07f;
  }
  return true;
}

float VehicleModel::glassAlbedo(const Eigen::Vector3d& n, const Eigen::Vector3d& d) const {
  // Dark tinted glass reflecting the sky (bright) or the street (dark), more
  // at grazing angles; never brighter than a third of the paint.
  const Eigen::Vector3d r = d - 2 * d.dot(n) * n;
  const double grazing = std::pow(1.0 - std::abs(d.dot(n)), 2.0);
  const double env = r.z() > 0 ? 0.55 + 0.35 * r.z() : 0.3;
  const double g = 0.06 + 0.2 * env * (0.3 + 0.7 * grazing);
  return static_cast<float>(std::min(g, 0.33 * dims_.paint));
}

Material VehicleModel::surface(int role, int face, const Eigen::Vector3d& p, const Eigen::Vector3d& n,
                               const Eigen::Vector3d& d, float* albedo) const {
  (void)face;
  const double W = dims_.width / 2, H = dims_.height, L = dims_.length / 2;
  const double ay = std::abs(p.y()), z = p.z();
  const bool front = n.x() > 0.6, rear = n.x() < -0.6, side = std::abs(n.y()) > 0.6, top = n.z() > 0.8;
  *albedo = role == kCargo ? dims_.paint2 : dims_.paint;
  auto glass = [&] {
    *albedo = glassAlbedo(n, d);
    return kGlass;
  };
  auto trim = [&](float a) {
    *albedo = a;
    return kTrim;
  };
  auto light = [&](float a) {
    *albedo = a;
    return kLight;
  };
  if (role == kChassis) {
    if (rear && ay > W - 0.45 && ay < W - 0.12) return light(0.12f);
    return trim(0.1f);
  }
  if (role == kGreenhouse) {
    if (top) return kCarPaint;
    const double u = std::clamp((z - belt_) / (H - belt_), 0.0, 1.0);
    const double x_front = windscreen_x0_ + (windscreen_x1_ - windscreen_x0_) * u;
    const double x_rear = rear_x0_ + (rear_x1_ - rear_x0_) * u;
    const double half = (W - 0.05) - 0.17 * u;  // greenhouse half width at this height
    const bool band = z > belt_ + 0.05 && z < H - 0.07;
    if (n.x() > 0.3) return band && ay < half - 0.08 ? glass() : kCarPaint;  // windscreen in its frame
    if (n.x() < -0.3) {
      if (dims_.kind == VehicleKind::kVan) return z > belt_ + 0.12 && z < H - 0.25 && ay > 0.04 && ay < W - 0.2 ? glass() : kCarPaint;
      return band && ay < half - 0.1 ? glass() : kCarPaint;
    }
    if (!band) return kCarPaint;
    if (dims_.kind == VehicleKind::kVan) return p.x() > L - 2.5 && p.x() < x_front - 0.1 ? glass() : kCarPaint;
    const double b_pillar = 0.5 * (windscreen_x1_ + rear_x1_);
    return p.x() < x_front - 0.09 && p.x() > x_rear + 0.12 && std::abs(p.x() - b_pillar) > 0.07 ? glass() : kCarPaint;
  }
  if (role == kTruckCab) {
    const double cab_h = windscreen_x1_;
    if (front && z > belt_ && z < cab_h - 0.25 && ay < W - 0.15) return glass();
    if (side && z > belt_ && z < cab_h - 0.3 && p.x() > windscreen_x0_ + 0.8 && p.x() < L - 0.3) return glass();
    if (front && z > 1.0 && z < 1.55 && ay < W - 0.45) return trim(0.1f);  // grille
  }
  if (role == kBusBody) {
    if (front && z > H - 0.3 && z < H - 0.08 && ay < W - 0.3) return trim(0.05f);  // destination sign
    if (front && z > belt_ && z < H - 0.32 && ay < W - 0.1) return glass();
    if (rear && z > 1.7 && z < H - 0.4 && ay < W - 0.2) return glass();
    if (side && z > 1.15 && z < H - 0.4 && std::abs(p.x()) < L - 0.5 &&
        std::fmod(p.x() + L - 0.5, 1.3) > 0.12)
      return glass();
    if (side && p.y() < 0 && p.x() > L - 1.5 && p.x() < L - 0.45 && z > 0.45 && z < H - 0.4) return glass();  // door
  }
  if (role == kCargo) {
    if (rear && ay < 0.02) return trim(0.2f);  // the doors' seam
    return kCarPaint;
  }
  // Body: lights, grille, bumpers, sills, wheel arches, door seams.
  if (front) {
    if (std::abs(z - light_z_) < 0.08 && ay > W - 0.42 && ay < W - 0.1) return light(0.95f);
    if (dims_.kind != VehicleKind::kBus && std::abs(z - light_z_ + 0.02) < 0.1 && ay < W - 0.5) return trim(0.08f);
    if (z < bumper_top_) return trim(0.2f);
  }
  if (rear) {
    if (std::abs(z - light_z_ - 0.05) < 0.09 && ay > W - 0.35 && ay < W - 0.08) return light(0.12f);
    if (z < bumper_top_) return trim(0.2f);
  }
  if (side) {
    for (const Wheel& w : wheels_) {
      if (std::hypot(p.x() - w.c.x(), z - w.c.z()) < w.r + 0.08) return trim(0.04f);  // arch: a dark recess
    }
    if (z < clearance_ + 0.1) return trim(0.2f);
    if (dims_.kind == VehicleKind::kCar && std::abs(p.x() - 0.5 * (windscreen_x1_ + rear_x1_)) < 0.012) {
      *albedo = 0.6f * dims_.paint;  // door seam
    }
  }
  if (top && role == kLowerBody && dims_.kind == VehicleKind::kCar) *albedo = 0.95f * dims_.paint;
  return kCarPaint;
}

double VehicleModel::distance(const Eigen::Vector3d& p) const {
  double best = std::numeric_limits<double>::infinity();
  for (const Convex& c : parts_) {
    double m = -std::numeric_limits<double>::infinity();
    for (const auto& pl : c.planes) m = std::max(m, pl.head<3>().dot(p) - pl[3]);
    best = std::min(best, m);
  }
  for (const Wheel& w : wheels_) {
    const Eigen::Vector2d q(std::hypot(p.x() - w.c.x(), p.z() - w.c.z()) - w.r, std::abs(p.y() - w.c.y()) - w.half_w);
    best = std::min(best, std::min(q.maxCoeff(), 0.0) + q.cwiseMax(0.0).norm());
  }
  return best;
}

std::vector<std::array<Eigen::Vector3d, 3>> VehicleModel::triangles() const {
  std::vector<std::array<Eigen::Vector3d, 3>> out;
  for (const Convex& c : parts_) {
    // Vertices: every triple of planes meeting at a point inside all others.
    const size_t n = c.planes.size();
    std::vector<std::vector<Eigen::Vector3d>> faces(n);
    for (size_t i = 0; i < n; ++i)
      for (size_t j = i + 1; j < n; ++j)
        for (size_t k = j + 1; k < n; ++k) {
          Eigen::Matrix3d A;
          A << c.planes[i].head<3>().transpose(), c.planes[j].head<3>().transpose(), c.planes[k].head<3>().transpose();
          if (std::abs(A.determinant()) < 1e-9) continue;
          const Eigen::Vector3d x = A.inverse() * Eigen::Vector3d(c.planes[i][3], c.planes[j][3], c.planes[k][3]);
          bool inside = true;
          for (const auto& pl : c.planes) inside = inside && pl.head<3>().dot(x) <= pl[3] + 1e-7;
          if (!inside) continue;
          for (size_t f : {i, j, k}) faces[f].push_back(x);
        }
    for (size_t f = 0; f < n; ++f) {
      auto& v = faces[f];
      if (v.size() < 3) continue;
      Eigen::Vector3d centre = Eigen::Vector3d::Zero();
      for (const auto& x : v) centre += x;
      centre /= static_cast<double>(v.size());
      const Eigen::Vector3d nrm = c.planes[f].head<3>();
      const Eigen::Vector3d e1 = (v[0] - centre).normalized(), e2 = nrm.cross(e1);
      std::sort(v.begin(), v.end(), [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
        return std::atan2((a - centre).dot(e2), (a - centre).dot(e1)) < std::atan2((b - centre).dot(e2), (b - centre).dot(e1));
      });
      for (size_t i = 1; i + 1 < v.size(); ++i) out.push_back({v[0], v[i], v[i + 1]});
    }
  }
  for (const Wheel& w : wheels_) {
    const int m = 16;
    auto P = [&](int i, double s) {
      const double a = 2 * M_PI * i / m;
      return Eigen::Vector3d(w.c.x() + w.r * std::cos(a), w.c.y() + s * w.half_w, w.c.z() + w.r * std::sin(a));
    };
    for (int i = 0; i < m; ++i) {
      out.push_back({P(i, -1), P(i + 1, -1), P(i + 1, 1)});
      out.push_back({P(i, -1), P(i + 1, 1), P(i, 1)});
      out.push_back({Eigen::Vector3d(w.c.x(), w.c.y() - w.half_w, w.c.z()), P(i + 1, -1), P(i, -1)});
      out.push_back({Eigen::Vector3d(w.c.x(), w.c.y() + w.half_w, w.c.z()), P(i, 1), P(i + 1, 1)});
    }
  }
  return out;
}

}  // namespace synth
}  // namespace fisheye_mapping
