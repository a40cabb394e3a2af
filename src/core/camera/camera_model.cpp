#include "fisheye_mapping/core/camera/camera_model.h"

#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace fisheye_mapping {
namespace {

// r^2 bound meaning "no bound" that survives the conversion to float.
constexpr double kNoBound = 1e30;

void requireFinite(const char* name, double value) {
  if (!std::isfinite(value)) {
    std::ostringstream msg;
    msg << name << " must be finite, got " << value;
    throw std::invalid_argument(msg.str());
  }
}

void requirePositive(const char* name, double value) {
  requireFinite(name, value);
  if (!(value > 0.0)) {
    std::ostringstream msg;
    msg << name << " must be positive, got " << value;
    throw std::invalid_argument(msg.str());
  }
}

// |value| <= limit (and finite): absurd values are a broken file, not a lens.
void requireWithin(const char* name, double value, double limit) {
  requireFinite(name, value);
  if (std::abs(value) > limit) {
    std::ostringstream msg;
    msg << name << " must lie in [" << -limit << ", " << limit << "], got " << value;
    throw std::invalid_argument(msg.str());
  }
}

void requireFocal(const char* name, double value) {
  requirePositive(name, value);
  if (value > kMaxFocalLength) {
    std::ostringstream msg;
    msg << name << " must lie in (0, " << kMaxFocalLength << "] pixels, got " << value;
    throw std::invalid_argument(msg.str());
  }
}

// The principal point lies inside the image ([-0.5, side - 0.5]: pixel
// centres at whole coordinates).
void requireInsideImage(const char* name, double value, int side, const char* side_name) {
  requireFinite(name, value);
  if (value < -0.5 || value > side - 0.5) {
    std::ostringstream msg;
    msg << name << " " << value << " is outside the image: the principal point must lie in [-0.5, " << side - 0.5
        << "] for " << side_name << " " << side;
    throw std::invalid_argument(msg.str());
  }
}

// Square-ish pixels: fx and fy within a factor of kMaxFocalRatio.
void requireFocalRatio(double fx, double fy) {
  if (std::max(fx, fy) > kMaxFocalRatio * std::min(fx, fy)) {
    std::ostringstream msg;
    msg << "fx " << fx << " and fy " << fy << " differ by more than a factor of " << kMaxFocalRatio
        << " (fx/fy = " << fx / fy << ")";
    throw std::invalid_argument(msg.str());
  }
}

void requireDistortion(const char* name, double value) { requireWithin(name, value, kMaxDistortionCoeff); }

void requireSize(int width, int height) {
  if (width <= 0 || height <= 0) {
    std::ostringstream msg;
    msg << "resolution must be positive, got " << width << "x" << height;
    throw std::invalid_argument(msg.str());
  }
  if (width > kMaxImageSide || height > kMaxImageSide) {
    std::ostringstream msg;
    msg << "resolution must be at most " << kMaxImageSide << "x" << kMaxImageSide << " pixels, got " << width << "x"
        << height;
    throw std::invalid_argument(msg.str());
  }
}

// Smallest r^2 > 0 where d/dr [r (1 + k1 r^2 + k2 r^4)] = 1 + 3 k1 s + 5 k2 s^2
// (s = r^2) reaches zero: beyond it the radial distortion folds back and cannot
// be inverted.
double radtanMaxR2(double k1, double k2) {
  const double a = 5.0 * k2;
  const double b = 3.0 * k1;
  double best = kNoBound;
  if (a == 0.0) {
    if (b < 0.0) best = -1.0 / b;
    return best;
  }
  const double disc = b * b - 4.0 * a;
  if (disc < 0.0) return best;
  const double sq = std::sqrt(disc);
  for (double s : {(-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)}) {
    if (s > 0.0 && s < best) best = s;
  }
  return best;
}

// Largest theta in [0, pi] up to which theta_d(theta) is increasing.
double kannalaBrandtMaxTheta(const FmCameraT<double>& cam) {
  const double step = 1e-3;
  double lo = 0.0;
  for (double t = step; t <= M_PI; t += step) {
    if (!(fm_kb_dtheta_d(&cam, t) > 0.0)) {
      double hi = t;
      for (int i = 0; i < 60; ++i) {
        const double mid = 0.5 * (lo + hi);
        (fm_kb_dtheta_d(&cam, mid) > 0.0 ? lo : hi) = mid;
      }
      return lo;
    }
    lo = t;
  }
  return M_PI;
}

}  // namespace

CameraModel CameraModel::make(CameraModelType type, const Intrinsics& in) {
  requireSize(in.width, in.height);
  requireFocal("fx", in.fx);
  requireFocal("fy", in.fy);
  requireFocalRatio(in.fx, in.fy);
  requireWithin("cx", in.cx, kMaxPrincipalPoint);
  requireWithin("cy", in.cy, kMaxPrincipalPoint);
  requireInsideImage("cx", in.cx, in.width, "width");
  requireInsideImage("cy", in.cy, in.height, "height");
  requireWithin("skew", in.skew, kMaxFocalLength);
  CameraModel cam;
  FmCameraT<double>& p = cam.params_;
  p.model = static_cast<int>(type);
  p.width = in.width;
  p.height = in.height;
  p.fx = in.fx;
  p.fy = in.fy;
  p.cx = in.cx;
  p.cy = in.cy;
  p.skew = in.skew;
  p.max_r2 = kNoBound;
  p.max_theta = M_PI;
  return cam;
}

CameraModel CameraModel::pinhole(const Intrinsics& in, double k1, double k2, double p1, double p2) {
  CameraModel cam = make(CameraModelType::kPinhole, in);
  requireDistortion("k1", k1);
  requireDistortion("k2", k2);
  requireDistortion("p1", p1);
  requireDistortion("p2", p2);
  FmCameraT<double>& p = cam.params_;
  p.k1 = k1;
  p.k2 = k2;
  p.p1 = p1;
  p.p2 = p2;
  p.max_r2 = radtanMaxR2(k1, k2);
  return cam;
}

CameraModel CameraModel::unified(const Intrinsics& in, double xi, double k1, double k2, double p1,
                                 double p2) {
  CameraModel cam = pinhole(in, k1, k2, p1, p2);
  requireFinite("xi", xi);
  if (xi < 0.0) {
    std::ostringstream msg;
    msg << "xi must be >= 0, got " << xi;
    throw std::invalid_argument(msg.str());
  }
  if (xi > kMaxUnifiedXi) {
    std::ostringstream msg;
    msg << "xi must be at most " << kMaxUnifiedXi << ", got " << xi;
    throw std::invalid_argument(msg.str());
  }
  cam.params_.model = FM_MODEL_UNIFIED;
  cam.params_.xi = xi;
  return cam;
}

CameraModel CameraModel::doubleSphere(const Intrinsics& in, double xi, double alpha) {
  CameraModel cam = make(CameraModelType::kDoubleSphere, in);
  requireFinite("xi", xi);
  requireFinite("alpha", alpha);
  if (xi <= -1.0 || xi >= 1.0) {
    std::ostringstream msg;
    msg << "xi must lie in (-1, 1) for the double sphere model, got " << xi;
    throw std::invalid_argument(msg.str());
  }
  if (alpha < 0.0 || alpha > 1.0) {
    std::ostringstream msg;
    msg << "alpha must lie in [0, 1], got " << alpha;
    throw std::invalid_argument(msg.str());
  }
  cam.params_.xi = xi;
  cam.params_.alpha = alpha;
  return cam;
}

CameraModel CameraModel::kannalaBrandt(const Intrinsics& in, double k1, double k2, double k3,
                                       double k4) {
  CameraModel cam = make(CameraModelType::kKannalaBrandt, in);
  requireDistortion("k1", k1);
  requireDistortion("k2", k2);
  requireDistortion("k3", k3);
  requireDistortion("k4", k4);
  FmCameraT<double>& p = cam.params_;
  p.k1 = k1;
  p.k2 = k2;
  p.k3 = k3;
  p.k4 = k4;
  p.max_theta = kannalaBrandtMaxTheta(p);
  return cam;
}

std::string CameraModel::name() const {
  switch (type()) {
    case CameraModelType::kPinhole:
      return "pinhole-radtan";
    case CameraModelType::kUnified:
      return "omni-radtan";
    case CameraModelType::kDoubleSphere:
      return "ds-none";
    case CameraModelType::kKannalaBrandt:
      return "pinhole-equidistant";
  }
  return "unknown";
}

bool CameraModel::project(const Eigen::Vector3d& p_C, Eigen::Vector2d* uv) const {
  double u = 0.0, v = 0.0;
  *uv = Eigen::Vector2d(NAN, NAN);
  // Non-finite and absurdly far points have no pixel (their squares would
  // overflow and land on the principal point); the origin has no direction.
  if (!p_C.allFinite()) return false;
  const double extent = p_C.cwiseAbs().maxCoeff();
  if (extent > kMaxProjectDistance || extent == 0.0) return false;
  Eigen::Vector3d p = p_C;
  // Every model depends on the direction alone: bring tiny points (whose
  // squares would underflow) to unit size by an exact power of two.
  if (extent < 1e-100) {
    int exponent = 0;
    std::frexp(extent, &exponent);
    p = Eigen::Vector3d(std::ldexp(p.x(), -exponent), std::ldexp(p.y(), -exponent), std::ldexp(p.z(), -exponent));
  }
  const int valid = fm_project(&params_, p.x(), p.y(), p.z(), &u, &v);
  *uv = Eigen::Vector2d(u, v);
  return valid != 0 && std::isfinite(u) && std::isfinite(v);
}

bool CameraModel::unproject(const Eigen::Vector2d& uv, Eigen::Vector3d* ray_C) const {
  double x = 0.0, y = 0.0, z = 0.0;
  if (!uv.allFinite()) {
    *ray_C = Eigen::Vector3d::Constant(NAN);
    return false;
  }
  const int valid = fm_unproject(&params_, uv.x(), uv.y(), &x, &y, &z);
  *ray_C = Eigen::Vector3d(x, y, z);
  return valid != 0 && ray_C->allFinite();
}

bool CameraModel::isInImage(const Eigen::Vector2d& uv, double margin) const {
  return fm_in_image(&params_, uv.x(), uv.y(), margin) != 0;
}

double CameraModel::maxValidAngle() const {
  // The valid domain of every model is a cone around the axis: walk out along
  // the +x meridian, then bisect the edge.
  auto valid = [this](double theta) {
    Eigen::Vector2d uv;
    return project(Eigen::Vector3d(std::sin(theta), 0.0, std::cos(theta)), &uv);
  };
  const double step = 1e-3;
  double lo = 0.0;
  for (double t = step; t <= M_PI; t += step) {
    if (!valid(t)) {
      double hi = t;
      for (int i = 0; i < 50; ++i) {
        const double mid = 0.5 * (lo + hi);
        (valid(mid) ? lo : hi) = mid;
      }
      return lo;
    }
    lo = t;
  }
  return M_PI;
}

CameraModel CameraModel::scaled(double scale, int width, int height) const {
  if (!(scale > 0.0) || !std::isfinite(scale) || width <= 0 || height <= 0) {
    throw std::invalid_argument("scaled camera: scale and size must be positive");
  }
  requireSize(width, height);
  requireFocal("scaled fx", params_.fx * scale);
  requireFocal("scaled fy", params_.fy * scale);
  CameraModel c = *this;
  c.params_.fx *= scale;
  c.params_.fy *= scale;
  c.params_.skew *= scale;
  c.params_.cx = (params_.cx + 0.5) * scale - 0.5;
  c.params_.cy = (params_.cy + 0.5) * scale - 0.5;
  c.params_.width = width;
  c.params_.height = height;
  return c;
}

CameraModel CameraModel::cropped(int x0, int y0, int width, int height) const {
  if (width <= 0 || height <= 0) {
    throw std::invalid_argument("cropped camera: size must be positive");
  }
  requireSize(width, height);
  CameraModel c = *this;
  c.params_.cx -= x0;
  c.params_.cy -= y0;
  c.params_.width = width;
  c.params_.height = height;
  return c;
}

std::vector<Eigen::Vector3f> pixelRays(const CameraModel& camera) {
  const int w = camera.width(), h = camera.height();
  std::vector<Eigen::Vector3f> rays(static_cast<size_t>(w) * h);
#pragma omp parallel for schedule(static)
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      Eigen::Vector3d ray;
      rays[static_cast<size_t>(v) * w + u] = camera.unproject(Eigen::Vector2d(u, v), &ray)
                                                 ? Eigen::Vector3f(ray.cast<float>())
                                                 : Eigen::Vector3f::Constant(NAN);
    }
  }
  return rays;
}

FmCameraT<float> CameraModel::floatParams() const {
  FmCameraT<float> f{};
  f.model = params_.model;
  f.width = params_.width;
  f.height = params_.height;
  f.reserved = 0;
  f.fx = static_cast<float>(params_.fx);
  f.fy = static_cast<float>(params_.fy);
  f.cx = static_cast<float>(params_.cx);
  f.cy = static_cast<float>(params_.cy);
  f.skew = static_cast<float>(params_.skew);
  f.xi = static_cast<float>(params_.xi);
  f.alpha = static_cast<float>(params_.alpha);
  f.k1 = static_cast<float>(params_.k1);
  f.k2 = static_cast<float>(params_.k2);
  f.k3 = static_cast<float>(params_.k3);
  f.k4 = static_cast<float>(params_.k4);
  f.p1 = static_cast<float>(params_.p1);
  f.p2 = static_cast<float>(params_.p2);
  f.max_r2 = static_cast<float>(params_.max_r2);
  f.max_theta = static_cast<float>(params_.max_theta);
  return f;
}

}  // namespace fisheye_mapping
