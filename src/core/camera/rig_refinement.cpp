#include "fisheye_mapping/core/camera/rig_refinement.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <random>
#include <sstream>
#include <stdexcept>

#include <opencv2/core/hal/hal.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

namespace fisheye_mapping {
namespace {

constexpr double kDeg = M_PI / 180.0;
// Weight of a match whose KLT refinement did not settle (its ORB keypoint
// kept): keypoints lay about 4 times farther from their epipolar planes than
// KLT-refined ones (0.12-0.2 vs 0.035-0.05 deg at the true calibration).
constexpr double kCoarseMatchWeight = 1.0 / 16.0;

void require(bool ok, const std::string& field, const std::string& what) {
  if (!ok) throw std::invalid_argument(field + ": " + what);
}

std::string sizeText(const cv::Mat& m) {
  std::ostringstream os;
  os << m.cols << "x" << m.rows;
  return os.str();
}

// Rotation exp(w) of an so(3) vector.
Eigen::Matrix3d expSo3(const Eigen::Vector3d& w) {
  const double a = w.norm();
  if (a < 1e-15) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(a, w / a).toRotationMatrix();
}

using Match = EpipolarMatch;

// Pixels per radian of the image around ray f (mean over two directions).
double pixelsPerRadian(const CameraModel& model, const Eigen::Vector3d& f) {
  const double d = 1e-4;
  Eigen::Vector2d uv, uv1, uv2;
  const Eigen::Vector3d a = f.unitOrthogonal(), b = f.cross(a);
  if (!model.project(f, &uv) || !model.project(f + d * a, &uv1) || !model.project(f + d * b, &uv2)) return 0.0;
  return std::sqrt(0.5 * ((uv1 - uv).squaredNorm() + (uv2 - uv).squaredNorm())) / d;
}

// Parameters of one camera's fit: rotation R_ref_cam = R0 * exp(w) and, with
// translation refinement, t = |t0| * normalize(t0_dir + B v).
class EpipolarModel {
 public:
  EpipolarModel(const Eigen::Matrix3d& R0, const Eigen::Vector3d& t0, bool refine_t)
      : R0_(R0), t0_(t0.normalized()), n_(refine_t ? 5 : 3) {
    Eigen::Vector3d a = std::abs(t0_.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    B_.col(0) = t0_.cross(a).normalized();
    B_.col(1) = t0_.cross(B_.col(0));
  }
  int params() const { return n_; }
  Eigen::Matrix3d rotation(const Eigen::VectorXd& x) const { return R0_ * expSo3(x.head<3>()); }
  // Unit translation direction.
  Eigen::Vector3d direction(const Eigen::VectorXd& x) const {
    if (n_ == 3) return t0_;
    return (t0_ + B_ * x.tail<2>()).normalized();
  }
  // Symmetric angular epipolar residual (radians): the triple product over the
  // mean sine of both rays' angles to the baseline.
  static double residual(const Eigen::Matrix3d& R, const Eigen::Vector3d& t, const Match& m) {
    const Eigen::Vector3d g = R * m.f_cam;
    const double e = m.f_ref.dot(t.cross(g));
    const double s = std::sqrt(0.5 * (t.cross(m.f_ref).squaredNorm() + t.cross(g).squaredNorm()));
    return e / s;
  }
  double residual(const Eigen::VectorXd& x, const Match& m) const { return residual(rotation(x), direction(x), m); }

 private:
  Eigen::Matrix3d R0_;
  Eigen::Vector3d t0_;
  Eigen::Matrix<double, 3, 2> B_;
  int n_;
};

// log of a rotation (an so(3) vector).
Eigen::Vector3d logSo3(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

// The rotation-only residual and its derivative with respect to a rotation
// delta applied on the camera's side, R -> R exp(delta):
//   g = R f_cam, e = (f_ref x t) . g, s = sqrt((|t x f_ref|^2 + |t x g|^2) / 2),
//   r = e / s; dr/dg = n / s + e (t . g) t / (2 s^3) (n = f_ref x t; |g| = 1
//   under rotations), dg/d(delta) = -R [f_cam]x, so dr/d(delta) =
//   f_cam x (R^T dr/dg).
double residualAndJacobian(const Eigen::Matrix3d& R, const Eigen::Vector3d& t, const Match& m, Eigen::Vector3d* J) {
  const Eigen::Vector3d g = R * m.f_cam;
  const Eigen::Vector3d n = m.f_ref.cross(t);
  const double e = n.dot(g);
  const double tg = t.dot(g);
  const double s2 = 0.5 * (t.cross(m.f_ref).squaredNorm() + t.cross(g).squaredNorm());
  const double s = std::sqrt(s2);
  const Eigen::Vector3d dr_dg = n / s + (e * tg / (2 * s2 * s)) * t;
  *J = m.f_cam.cross(R.transpose() * dr_dg);
  return e / s;
}

// The model at x and at the two points of each parameter's central
// difference, evaluated once (each is a rotation's exponential), for the
// residual and its numeric gradient of any number of matches.
class NumericJacobian {
 public:
  NumericJacobian(const EpipolarModel& model, const Eigen::VectorXd& x, double h = 1e-6)
      : n_(model.params()), h_(h), R_(model.rotation(x)), t_(model.direction(x)), Rp_(n_), Rm_(n_), tp_(n_), tm_(n_) {
    for (int k = 0; k < n_; ++k) {
      Eigen::VectorXd xp = x, xm = x;
      xp[k] += h, xm[k] -= h;
      Rp_[k] = model.rotation(xp), Rm_[k] = model.rotation(xm);
      tp_[k] = model.direction(xp), tm_[k] = model.direction(xm);
    }
  }
  // The residual of m at x; J (size params()) its gradient.
  double operator()(const Match& m, Eigen::VectorXd* J) const {
    for (int k = 0; k < n_; ++k)
      (*J)[k] = (EpipolarModel::residual(Rp_[k], tp_[k], m) - EpipolarModel::residual(Rm_[k], tm_[k], m)) / (2 * h_);
    return EpipolarModel::residual(R_, t_, m);
  }

 private:
  int n_;
  double h_;
  Eigen::Matrix3d R_;
  Eigen::Vector3d t_;
  std::vector<Eigen::Matrix3d> Rp_, Rm_;
  std::vector<Eigen::Vector3d> tp_, tm_;
};

// Gauss-Newton from x over the matches idx with Huber scale `huber` (radians;
// <= 0: plain least squares). Rotation only: analytic Jacobians of a delta
// on the camera's side, composed into x (R0 exp(x) exp(delta)); with the
// translation direction: numeric Jacobians (central differences). False when
// the normal equations are singular.
bool gaussNewton(const EpipolarModel& model, const std::vector<Match>& matches, const std::vector<int>& idx,
                 double huber, int iterations, Eigen::VectorXd* x) {
  const int n = model.params();
  if (n == 3) {
    for (int it = 0; it < iterations; ++it) {
      Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
      Eigen::Vector3d b = Eigen::Vector3d::Zero();
      const Eigen::Matrix3d R = model.rotation(*x);
      const Eigen::Vector3d t = model.direction(*x);
      Eigen::Vector3d J;
      for (int i : idx) {
        const Match& m = matches[i];
        const double r = residualAndJacobian(R, t, m, &J);
        const double rw = r * std::sqrt(m.weight);
        const double w = m.weight * ((huber <= 0 || std::abs(rw) <= huber) ? 1.0 : huber / std::abs(rw));
        H.noalias() += w * J * J.transpose();
        b.noalias() += w * J * r;
      }
      Eigen::LDLT<Eigen::Matrix3d> ldlt(H);
      if (ldlt.info() != Eigen::Success || !(H.diagonal().minCoeff() > 0)) return false;
      const Eigen::Vector3d delta = -ldlt.solve(b);
      if (!delta.allFinite()) return false;
      *x = logSo3(expSo3(x->head<3>()) * expSo3(delta));
      if (delta.norm() < 1e-9) break;  // radians: far below any residual
    }
    return x->allFinite();
  }
  for (int it = 0; it < iterations; ++it) {
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n, n);
    Eigen::VectorXd b = Eigen::VectorXd::Zero(n);
    const NumericJacobian jacobian(model, *x);
    Eigen::VectorXd J(n);
    for (int i : idx) {
      const Match& m = matches[i];
      const double r = jacobian(m, &J);
      // Huber on the residual scaled to the image's angular resolution.
      const double rw = r * std::sqrt(m.weight);
      const double w = m.weight * ((huber <= 0 || std::abs(rw) <= huber) ? 1.0 : huber / std::abs(rw));
      H.noalias() += w * J * J.transpose();
      b.noalias() += w * J * r;
    }
    Eigen::LDLT<Eigen::MatrixXd> ldlt(H);
    if (ldlt.info() != Eigen::Success || !(H.diagonal().minCoeff() > 0)) return false;
    const Eigen::VectorXd dx = -ldlt.solve(b);
    if (!dx.allFinite()) return false;
    *x += dx;
    if (dx.norm() < 1e-9) break;  // radians: far below any residual
  }
  return x->allFinite();
}

std::vector<int> inliersOf(const EpipolarModel& model, const std::vector<Match>& matches,
                           const Eigen::VectorXd& x, double threshold) {
  const Eigen::Matrix3d R = model.rotation(x);
  const Eigen::Vector3d t = model.direction(x);
  std::vector<int> in;
  for (int i = 0; i < int(matches.size()); ++i)
    if (std::abs(EpipolarModel::residual(R, t, matches[i])) < threshold) in.push_back(i);
  return in;
}

double rmsOf(const EpipolarModel& model, const std::vector<Match>& matches, const std::vector<int>& idx,
             const Eigen::VectorXd& x) {
  if (idx.empty()) return 0.0;
  const Eigen::Matrix3d R = model.rotation(x);
  const Eigen::Vector3d t = model.direction(x);
  double s = 0;
  for (int i : idx) s += std::pow(EpipolarModel::residual(R, t, matches[i]), 2);
  return std::sqrt(s / idx.size());
}

struct Features {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  std::vector<Eigen::Vector3d> rays;  // unit bearings, NaN where a keypoint does not unproject
};

// Bearings of keypoints (NaN where a keypoint does not unproject).
std::vector<Eigen::Vector3d> bearings(const CameraModel& model, const std::vector<cv::KeyPoint>& kps) {
  std::vector<Eigen::Vector3d> out(kps.size());
  for (size_t i = 0; i < kps.size(); ++i) {
    Eigen::Vector3d r;
    if (model.unproject(Eigen::Vector2d(kps[i].pt.x, kps[i].pt.y), &r)) out[i] = r.normalized();
    else out[i].setConstant(NAN);
  }
  return out;
}

// Guided matching: a reference feature is compared only with the support
// features whose rays (rotated by R into the reference frame) lie within
// max_residual of its epipolar plane around the baseline t (unit); among those,
// mutual best Hamming matches that pass the ratio test.
std::vector<std::pair<int, int>> matchGuided(const Features& a, const Features& b, const Eigen::Matrix3d& R,
                                             const Eigen::Vector3d& t, double max_residual, double ratio,
                                             int max_hamming) {
  const std::vector<Eigen::Vector3d>& fa = a.rays;
  const std::vector<Eigen::Vector3d>& fb = b.rays;
  std::vector<std::pair<int, int>> out;
  if (a.descriptors.empty() || b.descriptors.empty()) return out;
  // Angle of each ray's epipolar plane around the baseline.
  const Eigen::Vector3d e1 = t.unitOrthogonal(), e2 = t.cross(e1);
  const double min_sin = std::sin(2.0 * kDeg);
  struct Ray {
    double phi;
    int index;
    Eigen::Vector3d g;  // ray in the reference frame
    double s2;          // squared sine of its angle to the baseline
  };
  std::vector<Ray> rb;
  for (int j = 0; j < int(fb.size()); ++j) {
    if (!fb[j].allFinite()) continue;
    const Eigen::Vector3d g = R * fb[j];
    const double s2 = t.cross(g).squaredNorm();
    if (s2 < min_sin * min_sin) continue;
    rb.push_back({std::atan2(g.dot(e2), g.dot(e1)), j, g, s2});
  }
  std::sort(rb.begin(), rb.end(), [](const Ray& x, const Ray& y) { return x.phi < y.phi; });
  std::vector<double> phis(rb.size());
  for (size_t k = 0; k < rb.size(); ++k) phis[k] = rb[k].phi;
  const int na = int(fa.size()), nb = int(fb.size());
  std::vector<int> best_a(na, -1), best_b(nb, -1);
  std::vector<int> dist_a(na, INT32_MAX), second_a(na, INT32_MAX), dist_b(nb, INT32_MAX);
  const int bytes = a.descriptors.cols;
  for (int i = 0; i < na; ++i) {
    if (!fa[i].allFinite()) continue;
    const Eigen::Vector3d n = fa[i].cross(t);  // f . (t x g) = g . (f x t)
    const double s0 = n.norm();
    if (s0 < min_sin) continue;
    const double phi = std::atan2(fa[i].dot(e2), fa[i].dot(e1));
    const double delta = std::min(M_PI, 2.0 * max_residual / s0);
    const uint8_t* da = a.descriptors.ptr<uint8_t>(i);
    auto scan = [&](double lo, double hi) {
      const size_t k0 = std::lower_bound(phis.begin(), phis.end(), lo) - phis.begin();
      for (size_t k = k0; k < phis.size() && phis[k] <= hi; ++k) {
        const Ray& ray = rb[k];
        const int j = ray.index;
        const double e = ray.g.dot(n);
        if (e * e > max_residual * max_residual * 0.5 * (s0 * s0 + ray.s2)) continue;
        const int d = cv::hal::normHamming(da, b.descriptors.ptr<uint8_t>(j), bytes);
        if (d < dist_a[i]) {
          second_a[i] = dist_a[i];
          dist_a[i] = d;
          best_a[i] = j;
        } else if (d < second_a[i]) {
          second_a[i] = d;
        }
        if (d < dist_b[j]) dist_b[j] = d, best_b[j] = i;
      }
    };
    if (delta >= M_PI) {
      scan(-M_PI - 1, M_PI + 1);
      continue;
    }
    scan(phi - delta, phi + delta);
    if (phi - delta < -M_PI) scan(phi - delta + 2 * M_PI, M_PI + 1);
    if (phi + delta > M_PI) scan(-M_PI - 1, phi + delta - 2 * M_PI);
  }
  for (int i = 0; i < na; ++i) {
    const int j = best_a[i];
    if (j < 0 || best_b[j] != i || dist_a[i] > max_hamming) continue;
    if (second_a[i] != INT32_MAX && dist_a[i] >= ratio * second_a[i]) continue;
    out.emplace_back(i, j);
  }
  return out;
}


// Truncated RMS of the residuals of matches idx at x (radians): a residual
// beyond tau counts as tau.
double truncatedRms(const EpipolarModel& model, const std::vector<Match>& matches, const std::vector<int>& idx,
                    const Eigen::VectorXd& x, double tau) {
  if (idx.empty()) return 0.0;
  const Eigen::Matrix3d R = model.rotation(x);
  const Eigen::Vector3d t = model.direction(x);
  double s = 0;
  for (int i : idx) s += std::min(std::pow(EpipolarModel::residual(R, t, matches[i]), 2), tau * tau);
  return std::sqrt(s / idx.size());
}

// RANSAC from x0 over the matches idx, then Huber Gauss-Newton on the inliers
// (three rounds of re-selection). Returns the inliers (indices into matches)
// at the result *x.
// Without ransac: Huber Gauss-Newton over all of idx first (cheap; the
// held-out halves).
std::vector<int> robustFit(const EpipolarModel& model, const std::vector<Match>& matches, const std::vector<int>& idx,
                           const RigRefinementConfig& config, std::mt19937_64& rng, Eigen::VectorXd* x,
                           bool ransac = true) {
  const int n_par = model.params();
  const Eigen::VectorXd x0 = *x;
  const double thr = config.ransac_threshold_deg * kDeg;
  const auto inliers = [&](const Eigen::VectorXd& xs) {
    const Eigen::Matrix3d R = model.rotation(xs);
    const Eigen::Vector3d t = model.direction(xs);
    std::vector<int> in;
    for (int i : idx)
      if (std::abs(EpipolarModel::residual(R, t, matches[i])) < thr) in.push_back(i);
    return in;
  };
  if (int(idx.size()) < n_par) return inliers(x0);
  if (!ransac) {
    Eigen::VectorXd xr = x0;
    if (gaussNewton(model, matches, idx, config.huber_deg * kDeg, config.max_iterations, &xr)) *x = xr;
  }
  std::vector<int> best = inliers(*x);
  std::uniform_int_distribution<int> pick(0, int(idx.size()) - 1);
  for (int it = 0; ransac && it < config.ransac_iterations; ++it) {
    std::vector<int> sample;
    while (int(sample.size()) < n_par) {
      const int i = idx[pick(rng)];
      if (std::find(sample.begin(), sample.end(), i) == sample.end()) sample.push_back(i);
    }
    Eigen::VectorXd xs = x0;
    if (!gaussNewton(model, matches, sample, 0.0, 8, &xs)) continue;
    if ((xs - x0).head<3>().norm() > 2 * config.max_initial_residual_deg * kDeg) continue;
    std::vector<int> in = inliers(xs);
    if (in.size() > best.size()) {
      best.swap(in);
    }
  }
  for (int round = 0; round < 3 && int(best.size()) >= n_par; ++round) {
    Eigen::VectorXd xr = *x;
    if (!gaussNewton(model, matches, best, config.huber_deg * kDeg, config.max_iterations, &xr)) break;
    *x = xr;
    std::vector<int> in = inliers(*x);
    if (in == best) break;
    best.swap(in);
  }
  return best;
}

// Mahalanobis norm of x (in standard errors): x' H x / sigma^2 with H the
// weighted normal matrix of the residuals over idx at x and sigma^2 their
// weighted variance.
double significance(const EpipolarModel& model, const std::vector<Match>& matches, const std::vector<int>& idx,
                    const Eigen::VectorXd& x) {
  const int n = model.params();
  if (int(idx.size()) <= n) return 0.0;
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n, n);
  double rr = 0;
  Eigen::VectorXd J(n);
  const NumericJacobian jacobian(model, x);
  for (int i : idx) {
    const Match& m = matches[i];
    const double r = jacobian(m, &J);
    H.noalias() += m.weight * J * J.transpose();
    rr += m.weight * r * r;
  }
  const double sigma2 = rr / double(idx.size() - n);
  if (!(sigma2 > 0)) return 0.0;
  return std::sqrt(std::max(0.0, x.dot(H * x)) / sigma2);
}

}  // namespace

void RigRefinementConfig::validate() const {
  require(max_features >= 10, "max_features", "must be >= 10");
  require(pyramid_levels >= 1 && pyramid_levels <= 12, "pyramid_levels", "must be in [1, 12]");
  require(ratio > 0 && ratio <= 1, "ratio", "must be in (0, 1]");
  require(max_hamming >= 0 && max_hamming <= 256, "max_hamming", "must be in [0, 256]");
  require(klt_window >= 5 && klt_window <= 51, "klt_window", "must be in [5, 51]");
  require(min_inliers >= 5, "min_inliers", "must be >= 5");
  require(min_settled >= 0, "min_settled", "must be >= 0");
  require(max_initial_residual_deg > 0 && max_initial_residual_deg < 45, "max_initial_residual_deg",
          "must be in (0, 45)");
  require(ransac_threshold_deg > 0 && ransac_threshold_deg <= max_initial_residual_deg, "ransac_threshold_deg",
          "must be in (0, max_initial_residual_deg]");
  require(ransac_iterations >= 1, "ransac_iterations", "must be >= 1");
  require(huber_deg > 0, "huber_deg", "must be positive");
  require(max_iterations >= 1, "max_iterations", "must be >= 1");
  require(heldout_truncation_deg > 0 && heldout_truncation_deg <= max_initial_residual_deg, "heldout_truncation_deg",
          "must be in (0, max_initial_residual_deg]");
  require(min_significance >= 0 && std::isfinite(min_significance), "min_significance", "must be >= 0");
  require(min_generalization >= 0 && min_generalization <= 1, "min_generalization", "must be in [0, 1]");
  require(max_fit_matches == 0 || max_fit_matches >= min_inliers, "max_fit_matches", "must be 0 or >= min_inliers");
}

const char* toString(CameraRefinement::Status status) {
  switch (status) {
    case CameraRefinement::Status::kReference: return "reference";
    case CameraRefinement::Status::kApplied: return "applied";
    case CameraRefinement::Status::kTooFewInliers: return "too few inliers";
    case CameraRefinement::Status::kNotImproved: return "not improved";
  }
  return "?";
}

int RigRefinementResult::applied() const {
  return int(std::count_if(cameras.begin(), cameras.end(),
                           [](const CameraRefinement& c) { return c.status == CameraRefinement::Status::kApplied; }));
}

int RigRefinementResult::totalInliers() const {
  int n = 0;
  for (const auto& c : cameras)
    if (c.status != CameraRefinement::Status::kReference) n += c.inliers;
  return n;
}

Rig withRelativePose(const Rig& rig, int reference, int camera, const Eigen::Isometry3d& T_ref_cam) {
  const int n = int(rig.cameras.size());
  if (reference < 0 || reference >= n) throw std::invalid_argument("reference camera index out of range");
  if (camera < 0 || camera >= n) throw std::invalid_argument("camera index out of range");
  Rig out = rig;
  // In the base frame, then every camera re-expressed relative to cam0.
  out.cameras[camera].T_base_cam = rig.cameras[reference].T_base_cam * T_ref_cam;
  const Eigen::Isometry3d T_cam0_base = out.cameras[0].T_base_cam.inverse();
  for (auto& c : out.cameras) c.T_cam0_cam = T_cam0_base * c.T_base_cam;
  out.cameras[0].T_cam0_cam = Eigen::Isometry3d::Identity();
  return out;
}

RigMatcher::RigMatcher(const RigRefinementConfig& config, std::vector<cv::Mat> self_masks)
    : config_(config), self_masks_(std::move(self_masks)) {
  config_.validate();
  for (size_t c = 0; c < self_masks_.size(); ++c) {
    const cv::Mat& m = self_masks_[c];
    require(m.empty() || m.type() == CV_8UC1, "self-mask of camera " + std::to_string(c),
            "must be 8-bit single-channel (CV_8UC1)");
  }
}

const RigMatcher::Warp& RigMatcher::warpFor(const Rig& rig, int reference, int c) {
  const int n_cams = int(rig.cameras.size());
  if (int(warps_.size()) != n_cams || warp_reference_ != reference) {
    warps_.assign(n_cams, Warp());
    warp_reference_ = reference;
  }
  Warp& w = warps_[c];
  const CameraModel& ref_model = rig.cameras[reference].model;
  const Eigen::Matrix3d R_ref_cam =
      (rig.cameras[reference].T_base_cam.inverse() * rig.cameras[c].T_base_cam).linear();
  const bool fresh = w.width == ref_model.width() && w.height == ref_model.height() && !w.map_x.empty() &&
                     Eigen::AngleAxisd(w.R_ref_cam.transpose() * R_ref_cam).angle() < 0.25 * kDeg;
  if (fresh) return w;
  if (ref_rays_.empty() || ref_rays_width_ != ref_model.width() || ref_rays_height_ != ref_model.height() ||
      std::memcmp(&ref_rays_camera_, &ref_model.params(), sizeof(ref_rays_camera_)) != 0) {
    ref_rays_ = pixelRays(ref_model);
    ref_rays_width_ = ref_model.width(), ref_rays_height_ = ref_model.height();
    ref_rays_camera_ = ref_model.params();
  }
  const std::vector<Eigen::Vector3f>& rays = ref_rays_;
  const int width = ref_model.width(), height = ref_model.height();
  const CameraModel& model = rig.cameras[c].model;
  const Eigen::Matrix3f R_cam_ref = R_ref_cam.transpose().cast<float>();
  const cv::Mat& detect = detect_masks_[c];
  w.map_x.create(height, width, CV_32FC1);
  w.map_y.create(height, width, CV_32FC1);
  cv::Mat valid(height, width, CV_8UC1);
#pragma omp parallel for schedule(static)
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector3f& r = rays[size_t(v) * width + u];
      Eigen::Vector2d uv;
      const bool ok = r.allFinite() && model.project((R_cam_ref * r).cast<double>(), &uv) && model.isInImage(uv, 1.0) &&
                      (detect.empty() || detect.at<uint8_t>(int(std::lround(uv.y())), int(std::lround(uv.x()))) != 0);
      w.map_x.at<float>(v, u) = ok ? float(uv.x()) : -1.0f;
      w.map_y.at<float>(v, u) = ok ? float(uv.y()) : -1.0f;
      valid.at<uint8_t>(v, u) = ok ? 255 : 0;
    }
  }
  // Keep ORB's and KLT's windows off the border of the resampled view.
  cv::erode(valid, w.feature_mask, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(33, 33)));
  cv::convertMaps(w.map_x, w.map_y, w.map_fixed, w.map_fraction, CV_16SC2);
  w.R_ref_cam = R_ref_cam;
  w.width = width, w.height = height;
  return w;
}

std::vector<std::vector<EpipolarMatch>> RigMatcher::match(const Rig& rig, int reference,
                                                          const std::vector<cv::Mat>& set, std::vector<int>* raw,
                                                          const std::vector<double>& band_deg) {
  const int n_cams = int(rig.cameras.size());
  require(reference >= 0 && reference < n_cams, "reference",
          "camera index " + std::to_string(reference) + " is not in [0, " + std::to_string(n_cams) + ")");
  require(int(set.size()) == n_cams, "frame set",
          "has " + std::to_string(set.size()) + " images, the rig has " + std::to_string(n_cams) + " cameras");
  require(self_masks_.empty() || int(self_masks_.size()) == n_cams, "self_masks",
          "need none or one per camera (" + std::to_string(n_cams) + "), got " + std::to_string(self_masks_.size()));
  for (int c = 0; c < n_cams; ++c) {
    const cv::Mat& im = set[c];
    const RigCamera& cam = rig.cameras[c];
    if (im.empty()) {
      require(c != reference, cam.name, "image is empty");
      continue;
    }
    require(im.type() == CV_8UC1, cam.name, "image must be 8-bit single-channel (CV_8UC1)");
    require(im.cols == cam.model.width() && im.rows == cam.model.height(), cam.name,
            "image is " + sizeText(im) + ", calibration says " + std::to_string(cam.model.width()) + "x" +
                std::to_string(cam.model.height()));
  }
  if (int(detect_masks_.size()) != n_cams) {
    // Where features may be detected: outside the self-mask.
    detect_masks_.assign(n_cams, cv::Mat());
    for (int c = 0; c < n_cams && !self_masks_.empty(); ++c) {
      const cv::Mat& m = self_masks_[c];
      if (m.empty()) continue;
      const RigCamera& cam = rig.cameras[c];
      if (m.cols != cam.model.width() || m.rows != cam.model.height()) {
        detect_masks_.clear();
        throw std::invalid_argument("self-mask of " + cam.name + ": is " + sizeText(m) + ", calibration says " +
                                    std::to_string(cam.model.width()) + "x" + std::to_string(cam.model.height()));
      }
      detect_masks_[c] = m == 0;
    }
  }
  // Calibrated pose of each camera relative to the reference.
  const Eigen::Isometry3d T_base_ref = rig.cameras[reference].T_base_cam;
  std::vector<Eigen::Isometry3d> T_ref(n_cams);
  for (int c = 0; c < n_cams; ++c) {
    T_ref[c] = T_base_ref.inverse() * rig.cameras[c].T_base_cam;
    if (c != reference)
      require(T_ref[c].translation().norm() > 1e-6, rig.cameras[c].name, "has no baseline to the reference camera");
  }
  // Features come from the reference image and from each support image,
  // resampled (warp_support) into the reference camera's geometry through the
  // current rotation: patches then look alike in both, whatever the cameras'
  // yaw, and only parallax separates them. feature_mask: where features may
  // lie (outside self-masks, inside the resampled view).
  const CameraModel& ref_model = rig.cameras[reference].model;
  const auto geometry = [&](int c) -> const CameraModel& {
    return config_.warp_support ? ref_model : rig.cameras[c].model;
  };
  std::vector<cv::Mat> image(n_cams), feature_mask = detect_masks_;
  for (int c = 0; c < n_cams; ++c) {
    if (set[c].empty()) continue;
    if (!config_.warp_support || c == reference) {
      image[c] = set[c];
    } else {
      const Warp& w = warpFor(rig, reference, c);
      // Fixed-point maps (1/32 px), remap's fast path.
      cv::remap(set[c], image[c], w.map_fixed, w.map_fraction, cv::INTER_LINEAR, cv::BORDER_CONSTANT);  // new buffer
      feature_mask[c] = w.feature_mask;
    }
  }
  const auto masked = [&](int c, const cv::Point2f& p) {
    if (feature_mask[c].empty()) return false;
    const int u = int(std::lround(p.x)), v = int(std::lround(p.y));
    if (u < 0 || v < 0 || u >= feature_mask[c].cols || v >= feature_mask[c].rows) return true;
    return feature_mask[c].at<uint8_t>(v, u) == 0;
  };
  std::vector<Features> feats(n_cams);
#pragma omp parallel for schedule(dynamic)
  for (int c = 0; c < n_cams; ++c) {
    if (image[c].empty()) continue;
    auto orb = cv::ORB::create(config_.max_features, 1.2f, config_.pyramid_levels, 31, 0, 2, cv::ORB::HARRIS_SCORE,
                               31, 10);
    orb->detectAndCompute(image[c], feature_mask[c].empty() ? cv::noArray() : cv::InputArray(feature_mask[c]),
                          feats[c].keypoints, feats[c].descriptors);
    feats[c].rays = bearings(geometry(c), feats[c].keypoints);
  }
  std::vector<std::vector<Match>> found(n_cams);
  if (raw) raw->assign(n_cams, 0);
  // The reference image's KLT pyramid and its derivatives, once for every
  // support camera (calcOpticalFlowPyrLK given images builds both per call).
  const cv::Size klt_window(config_.klt_window, config_.klt_window);
  constexpr int kKltLevels = 1;
  std::vector<cv::Mat> ref_pyramid;
  if (config_.subpixel) cv::buildOpticalFlowPyramid(image[reference], ref_pyramid, klt_window, kKltLevels, true);
#pragma omp parallel for schedule(dynamic)
  for (int c = 0; c < n_cams; ++c) {
    if (c == reference || image[c].empty()) continue;
    // Warped features are rays of the reference frame: R = I for the epipolar window.
    const Eigen::Matrix3d R_match =
        config_.warp_support ? Eigen::Matrix3d::Identity() : Eigen::Matrix3d(T_ref[c].linear());
    const double band = int(band_deg.size()) > c && band_deg[c] > 0
                            ? std::min(band_deg[c], config_.max_initial_residual_deg)
                            : config_.max_initial_residual_deg;
    const auto dm = matchGuided(feats[reference], feats[c], R_match, T_ref[c].translation().normalized(), band * kDeg,
                                config_.ratio, config_.max_hamming);
    if (raw) (*raw)[c] = int(dm.size());
    std::vector<cv::Point2f> p_ref, p_cam;
    for (const auto& [i, j] : dm) {
      p_ref.push_back(feats[reference].keypoints[i].pt);
      p_cam.push_back(feats[c].keypoints[j].pt);
    }
    std::vector<uint8_t> ok(p_ref.size(), 1), coarse(p_ref.size(), 0);
    if (config_.subpixel && !p_ref.empty()) {
      // The support keypoint moved to where the reference patch fits best.
      std::vector<cv::Point2f> refined = p_cam;
      std::vector<float> err;
      std::vector<cv::Mat> pyramid;
      cv::buildOpticalFlowPyramid(image[c], pyramid, klt_window, kKltLevels, false);
      cv::calcOpticalFlowPyrLK(ref_pyramid, pyramid, p_ref, refined, ok, err, klt_window, kKltLevels,
                               cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.005),
                               cv::OPTFLOW_USE_INITIAL_FLOW);
      // Where KLT does not settle within 3 px the match goes, unless too
      // few settle to make a fit (min_settled): then those keep their
      // keypoints, weighted as their precision, 4 times coarser (1/16).
      // Patches of a wide baseline differ in scale and blur: on the surround
      // rig of docs/depth.md KLT slid off 54 of a mirror camera's 58
      // matches, whose keypoints lay within 0.12-0.2 deg of their epipolar
      // planes at the true calibration. (Kept everywhere, the coarse matches
      // moved the default rig's well-matched cameras: 0.06 deg and 15 mm
      // worse on two of the self-calibration drives.)
      int settled = 0;
      for (size_t i = 0; i < refined.size(); ++i) {
        if (ok[i] && cv::norm(refined[i] - p_cam[i]) < 3.0) {
          p_cam[i] = refined[i];
          ++settled;
        } else {
          coarse[i] = 1;
        }
      }
      for (size_t i = 0; i < refined.size(); ++i) ok[i] = !coarse[i] || settled < config_.min_settled;
    }
    const CameraModel& m_ref = rig.cameras[reference].model;
    const CameraModel& m_cam = rig.cameras[c].model;
    // The warp's rotation (not exactly the rig's: maps are kept while it moves little).
    const Eigen::Matrix3d R_cam_ref =
        config_.warp_support ? warps_[c].R_ref_cam.transpose() : Eigen::Matrix3d(T_ref[c].linear().transpose());
    for (size_t i = 0; i < p_ref.size(); ++i) {
      if (!ok[i] || masked(reference, p_ref[i]) || masked(c, p_cam[i])) continue;
      Match m;
      if (!m_ref.unproject(Eigen::Vector2d(p_ref[i].x, p_ref[i].y), &m.f_ref)) continue;
      if (!geometry(c).unproject(Eigen::Vector2d(p_cam[i].x, p_cam[i].y), &m.f_cam)) continue;
      m.f_ref.normalize(), m.f_cam.normalize();
      // A warped pixel's ray is the support camera's ray rotated by the warp's rotation.
      if (config_.warp_support) m.f_cam = R_cam_ref * m.f_cam;
      if (config_.weight_by_resolution) {
        // Pixel noise in both images as an angle: 1/s0^2 + 1/s1^2.
        const double s0 = pixelsPerRadian(m_ref, m.f_ref), s1 = pixelsPerRadian(m_cam, m.f_cam);
        if (!(s0 > 0 && s1 > 0)) continue;
        m.weight = 1.0 / (1.0 / (s0 * s0) + 1.0 / (s1 * s1));
      }
      if (coarse[i]) m.weight *= kCoarseMatchWeight;
      found[c].push_back(m);
    }
  }
  return found;
}

CameraRefinement estimateCameraCorrection(const std::vector<EpipolarMatch>& matches, const Eigen::Isometry3d& T_ref_cam,
                                          const RigRefinementConfig& config, std::mt19937_64& rng,
                                          Eigen::Isometry3d* T_estimated, const std::vector<int>& groups) {
  require(groups.empty() || groups.size() == matches.size(), "groups", "need none or one per match");
  config.validate();
  CameraRefinement out;
  out.status = CameraRefinement::Status::kTooFewInliers;
  out.matches = int(matches.size());
  *T_estimated = T_ref_cam;
  const Eigen::Vector3d t0 = T_ref_cam.translation();
  require(t0.norm() > 1e-6, "camera", "has no baseline to the reference camera");
  const EpipolarModel model(T_ref_cam.linear(), t0, config.refine_translation);
  const Eigen::Vector3d t_dir = t0.normalized();
  const Eigen::Matrix3d R0 = T_ref_cam.linear();

  // Candidates: near the epipolar plane at the calibration, away from the
  // epipoles, and in front of both cameras (or too distant to tell).
  std::vector<Match> cand;
  std::vector<int> cand_group;  // the frame set (group) of each candidate
  const double min_sin = std::sin(2.0 * kDeg);
  for (size_t mi = 0; mi < matches.size(); ++mi) {
    const Match& m = matches[mi];
    if (!m.f_ref.allFinite() || !m.f_cam.allFinite() || !(m.weight > 0)) continue;
    const Eigen::Vector3d g = R0 * m.f_cam;
    if (t_dir.cross(m.f_ref).norm() < min_sin || t_dir.cross(g).norm() < min_sin) continue;
    if (std::abs(EpipolarModel::residual(R0, t_dir, m)) > config.max_initial_residual_deg * kDeg) continue;
    const double parallax = std::acos(std::clamp(m.f_ref.dot(g), -1.0, 1.0));
    if (parallax > 1.0 * kDeg) {
      // lambda_ref f_ref - lambda_cam g = t in the least-squares sense.
      Eigen::Matrix<double, 3, 2> A;
      A << m.f_ref, -g;
      const Eigen::Vector2d lambda = (A.transpose() * A).ldlt().solve(A.transpose() * t0);
      if (!(lambda.x() > 0 && lambda.y() > 0)) continue;
    }
    cand.push_back(m);
    cand_group.push_back(groups.empty() ? 0 : groups[mi]);
  }
  out.candidates = int(cand.size());
  if (config.max_fit_matches > 0 && int(cand.size()) > config.max_fit_matches) {
    // An even subsample (matches come in image order: every part of the image keeps its share).
    std::vector<Match> sub;
    std::vector<int> sub_group;
    sub.reserve(config.max_fit_matches);
    const double step = double(cand.size()) / config.max_fit_matches;
    for (int k = 0; k < config.max_fit_matches; ++k) {
      sub.push_back(cand[size_t(k * step)]);
      sub_group.push_back(cand_group[size_t(k * step)]);
    }
    cand.swap(sub);
    cand_group.swap(sub_group);
  }
  if (!cand.empty()) {
    // Relative weights: 1 at the median, so that Huber's scale stays in degrees.
    std::vector<double> w;
    for (const Match& m : cand) w.push_back(m.weight);
    std::nth_element(w.begin(), w.begin() + w.size() / 2, w.end());
    for (Match& m : cand) m.weight /= w[w.size() / 2];
  }
  const int n_par = model.params();
  const Eigen::VectorXd x0 = Eigen::VectorXd::Zero(n_par);
  std::vector<int> all(cand.size());
  std::iota(all.begin(), all.end(), 0);
  const double thr = config.ransac_threshold_deg * kDeg;
  const std::vector<int> inliers_before = inliersOf(model, cand, x0, thr);
  Eigen::VectorXd x = x0;
  std::vector<int> best;
  if (int(cand.size()) >= std::max(config.min_inliers, n_par)) best = robustFit(model, cand, all, config, rng, &x);
  out.inliers = int(best.size());
  if (out.inliers < config.min_inliers) {
    out.message = std::to_string(out.candidates) + " candidate matches, " + std::to_string(out.inliers) +
                  " inliers; need " + std::to_string(config.min_inliers) + " inliers";
    out.rms_before_deg = out.rms_after_deg = rmsOf(model, cand, inliers_before, x0) / kDeg;
    return out;
  }
  out.rms_before_deg = rmsOf(model, cand, best, x0) / kDeg;
  out.rms_after_deg = rmsOf(model, cand, best, x) / kDeg;
  const Eigen::Matrix3d dR = expSo3(x.head<3>());
  const Eigen::AngleAxisd aa(dR);
  out.correction_deg = aa.angle() / kDeg;
  out.correction_axis = aa.angle() > 0 ? aa.axis() : Eigen::Vector3d::Zero();
  const double sig = significance(model, cand, best, x);
  out.standard_error_deg = sig > 0 ? x.norm() / sig / kDeg : INFINITY;

  // Held out: each half of the candidates fitted on its own and scored on
  // the other half, against the calibration's score there. With matches of
  // several frame sets the halves are whole frame sets (alternate groups): a
  // bias of one scene (near points and the calibrated translation's error)
  // then does not carry over to the half it is scored on. Else alternate
  // matches.
  const double tau = config.heldout_truncation_deg * kDeg;
  std::vector<int> half[2];
  std::vector<int> ids = cand_group;
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  for (int i = 0; i < int(cand.size()); ++i) {
    const int rank = int(std::lower_bound(ids.begin(), ids.end(), cand_group[i]) - ids.begin());
    half[ids.size() >= 2 ? rank % 2 : i % 2].push_back(i);
  }
  double before = 0, after = 0;
  bool both_better = true;
  for (int k = 0; k < 2; ++k) {
    Eigen::VectorXd xk = x0;
    robustFit(model, cand, half[k], config, rng, &xk, false);
    const double b = truncatedRms(model, cand, half[1 - k], x0, tau);
    const double a = truncatedRms(model, cand, half[1 - k], xk, tau);
    before += 0.5 * b, after += 0.5 * a;
    if (!(a < b)) both_better = false;
  }
  out.heldout_before_deg = before / kDeg;
  out.heldout_after_deg = after / kDeg;
  std::ostringstream why;
  why.precision(4);
  if (!both_better) {
    out.status = CameraRefinement::Status::kNotImproved;
    why << "held-out residual not lower in both halves (" << out.heldout_before_deg << " -> "
        << out.heldout_after_deg << " deg)";
    out.message = why.str();
    return out;
  }
  // What the fit explains of the residual on matches it was not fitted to
  // must be a fair share of what it explains on its own: a genuine error
  // explains about as much of both; a fit to one scene's bias (near points
  // and the calibrated translation's error) mostly of its own.
  const double explained_in = std::sqrt(std::max(0.0, std::pow(out.rms_before_deg, 2) - std::pow(out.rms_after_deg, 2)));
  const double explained_out =
      std::sqrt(std::max(0.0, std::pow(out.heldout_before_deg, 2) - std::pow(out.heldout_after_deg, 2)));
  if (explained_out < config.min_generalization * explained_in) {
    out.status = CameraRefinement::Status::kNotImproved;
    why << "the fit explains " << explained_in << " deg of its own residual but only " << explained_out
        << " deg of the held-out one";
    out.message = why.str();
    return out;
  }
  if (sig < config.min_significance) {
    out.status = CameraRefinement::Status::kNotImproved;
    why << "correction " << out.correction_deg << " deg is within " << config.min_significance
        << " standard errors (" << out.standard_error_deg << " deg)";
    out.message = why.str();
    return out;
  }
  out.status = CameraRefinement::Status::kApplied;
  out.correction = dR;
  Eigen::Isometry3d T_new = T_ref_cam;
  T_new.linear() = model.rotation(x);
  T_new.translation() = model.direction(x) * t0.norm();
  out.translation_change_deg = std::acos(std::clamp(model.direction(x).dot(t_dir), -1.0, 1.0)) / kDeg;
  *T_estimated = T_new;
  return out;
}

namespace {

// Keeps an even subsample of at most `most` elements (0: all); matches come
// in image order, so every part of the image keeps its share.
template <typename T>
void keepEvenSubsample(std::vector<T>* v, int most) {
  if (most <= 0 || int(v->size()) <= most) return;
  std::vector<T> sub;
  sub.reserve(most);
  const double step = double(v->size()) / most;
  for (int k = 0; k < most; ++k) sub.push_back((*v)[size_t(k * step)]);
  v->swap(sub);
}

// Relative weights: 1 at the median, so that Huber's scale stays in degrees.
template <typename T>
void normalizeWeights(std::vector<T>* v) {
  if (v->empty()) return;
  std::vector<double> w;
  for (const T& m : *v) w.push_back(m.weight);
  std::nth_element(w.begin(), w.begin() + w.size() / 2, w.end());
  for (T& m : *v) m.weight /= w[w.size() / 2];
}

// One metric match prepared for the pose fit: the point, the support
// camera's bearing and two unit vectors across it (the residual is the
// predicted bearing's components along them: its angle to the observed one,
// in radians, for small angles).
struct PoseObs {
  Eigen::Vector3d X, f, b1, b2;
  double weight;
  int group;
};

// Residual of o at (R, t) and, when J is given, its Jacobian with respect
// to (delta, dv): R -> R exp(delta), t -> t + dv. p = R^T (X - t), u = p / |p|:
// dp/d(delta) = [p]x, dp/d(dv) = -R^T, du/dp = (I - u u^T) / |p|.
bool poseResidual(const Eigen::Matrix3d& R, const Eigen::Vector3d& t, const PoseObs& o, Eigen::Vector2d* r,
                  Eigen::Matrix<double, 2, 6>* J = nullptr) {
  const Eigen::Vector3d p = R.transpose() * (o.X - t);
  const double n = p.norm();
  if (!(n > 1e-6)) return false;
  const Eigen::Vector3d u = p / n;
  if (u.dot(o.f) <= 0) return false;
  *r << o.b1.dot(u), o.b2.dot(u);
  if (J) {
    Eigen::Matrix<double, 2, 3> B;
    B.row(0) = o.b1.transpose();
    B.row(1) = o.b2.transpose();
    const Eigen::Matrix<double, 2, 3> dudp = B * (Eigen::Matrix3d::Identity() - u * u.transpose()) / n;
    Eigen::Matrix3d px;
    px << 0, -p.z(), p.y(), p.z(), 0, -p.x(), -p.y(), p.x(), 0;
    J->leftCols<3>() = dudp * px;
    J->rightCols<3>() = -dudp * R.transpose();
  }
  return true;
}

struct PoseFit {
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
};

// Huber Gauss-Newton over obs idx from *fit. False when singular.
bool poseGaussNewton(const std::vector<PoseObs>& obs, const std::vector<int>& idx, double huber, int iterations,
                     PoseFit* fit, Eigen::Matrix<double, 6, 6>* H_out = nullptr) {
  if (idx.size() < 6) return false;
  for (int it = 0; it < iterations; ++it) {
    Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
    Eigen::Vector2d r;
    Eigen::Matrix<double, 2, 6> J;
    for (int i : idx) {
      if (!poseResidual(fit->R, fit->t, obs[i], &r, &J)) continue;
      const double rw = r.norm() * std::sqrt(obs[i].weight);
      const double w = obs[i].weight * ((huber <= 0 || rw <= huber) ? 1.0 : huber / rw);
      H.noalias() += w * J.transpose() * J;
      b.noalias() += w * J.transpose() * r;
    }
    if (H_out) *H_out = H;
    Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(H);
    if (ldlt.info() != Eigen::Success || !(H.diagonal().minCoeff() > 0)) return false;
    const Eigen::Matrix<double, 6, 1> d = -ldlt.solve(b);
    if (!d.allFinite()) return false;
    fit->R = fit->R * expSo3(d.head<3>());
    fit->t += d.tail<3>();
    // 1e-8 rad, 1 um: far below any standard error (Huber's reweighting
    // converges linearly: the tighter 1e-9 rad / 0.1 um cost 2 more iterations a fit).
    if (d.head<3>().norm() < 1e-8 && d.tail<3>().norm() < 1e-6) break;
  }
  return true;
}

double poseTruncatedRms(const std::vector<PoseObs>& obs, const std::vector<int>& idx, const PoseFit& fit, double tau) {
  if (idx.empty()) return 0.0;
  double s = 0;
  Eigen::Vector2d r;
  for (int i : idx) s += poseResidual(fit.R, fit.t, obs[i], &r) ? std::min(r.squaredNorm(), tau * tau) : tau * tau;
  return std::sqrt(s / idx.size());
}

std::vector<int> poseInliers(const std::vector<PoseObs>& obs, const std::vector<int>& idx, const PoseFit& fit,
                             double thr) {
  std::vector<int> in;
  Eigen::Vector2d r;
  for (int i : idx)
    if (poseResidual(fit.R, fit.t, obs[i], &r) && r.norm() < thr) in.push_back(i);
  return in;
}

double poseRms(const std::vector<PoseObs>& obs, const std::vector<int>& idx, const PoseFit& fit) {
  return poseTruncatedRms(obs, idx, fit, INFINITY);
}

// Huber fit over idx, then inliers re-selected at thr (three rounds).
std::vector<int> robustPoseFit(const std::vector<PoseObs>& obs, const std::vector<int>& idx,
                               const RigRefinementConfig& config, PoseFit* fit) {
  const double huber = config.huber_deg * kDeg, thr = config.ransac_threshold_deg * kDeg;
  PoseFit f = *fit;
  if (poseGaussNewton(obs, idx, huber, config.max_iterations, &f)) *fit = f;
  std::vector<int> best = poseInliers(obs, idx, *fit, thr);
  for (int round = 0; round < 3 && best.size() >= 6; ++round) {
    f = *fit;
    if (!poseGaussNewton(obs, best, huber, config.max_iterations, &f)) break;
    *fit = f;
    std::vector<int> in = poseInliers(obs, idx, *fit, thr);
    if (in == best) break;
    best.swap(in);
  }
  return best;
}

}  // namespace

CameraRefinement estimateCameraPose(const std::vector<MetricMatch>& matches, const Eigen::Isometry3d& T_ref_cam,
                                    const RigRefinementConfig& config, Eigen::Isometry3d* T_estimated,
                                    const std::vector<int>& groups) {
  require(groups.empty() || groups.size() == matches.size(), "groups", "need none or one per match");
  config.validate();
  CameraRefinement out;
  out.status = CameraRefinement::Status::kTooFewInliers;
  out.matches = int(matches.size());
  *T_estimated = T_ref_cam;
  const PoseFit cur{T_ref_cam.linear(), T_ref_cam.translation()};
  std::vector<PoseObs> obs;
  const double max_initial = config.max_initial_residual_deg * kDeg;
  for (size_t i = 0; i < matches.size(); ++i) {
    const MetricMatch& m = matches[i];
    if (!m.X_ref.allFinite() || !m.f_cam.allFinite() || !(m.weight > 0) || !(m.f_cam.norm() > 0)) continue;
    PoseObs o;
    o.X = m.X_ref;
    o.f = m.f_cam.normalized();
    o.b1 = o.f.unitOrthogonal();
    o.b2 = o.f.cross(o.b1);
    o.weight = m.weight;
    o.group = groups.empty() ? 0 : groups[i];
    Eigen::Vector2d r;
    if (!poseResidual(cur.R, cur.t, o, &r) || r.norm() > max_initial) continue;
    obs.push_back(o);
  }
  out.candidates = int(obs.size());
  keepEvenSubsample(&obs, config.max_fit_matches);
  normalizeWeights(&obs);
  std::vector<int> all(obs.size());
  std::iota(all.begin(), all.end(), 0);
  const double thr = config.ransac_threshold_deg * kDeg;
  PoseFit fit = cur;
  std::vector<int> best;
  if (int(obs.size()) >= std::max(config.min_inliers, 6)) best = robustPoseFit(obs, all, config, &fit);
  out.inliers = int(best.size());
  if (out.inliers < config.min_inliers) {
    out.message = std::to_string(out.candidates) + " candidate metric matches, " + std::to_string(out.inliers) +
                  " inliers; need " + std::to_string(config.min_inliers) + " inliers";
    const std::vector<int> in0 = poseInliers(obs, all, cur, thr);
    out.rms_before_deg = out.rms_after_deg = poseRms(obs, in0, cur) / kDeg;
    return out;
  }
  out.rms_before_deg = poseRms(obs, best, cur) / kDeg;
  out.rms_after_deg = poseRms(obs, best, fit) / kDeg;
  const Eigen::Matrix3d dR = cur.R.transpose() * fit.R;
  const Eigen::AngleAxisd aa(dR);
  out.correction_deg = aa.angle() / kDeg;
  out.correction_axis = aa.angle() > 0 ? aa.axis() : Eigen::Vector3d::Zero();
  out.correction = dR;
  const Eigen::Vector3d dt = fit.t - cur.t;
  out.translation_change_mm = 1000 * dt.norm();
  // The translation's marginal covariance: sigma^2 (H^-1)_tt at the fit.
  Eigen::Matrix<double, 6, 6> H;
  PoseFit at = fit;
  double sig = 0;
  Eigen::Matrix3d cov_t = Eigen::Matrix3d::Constant(NAN);
  if (poseGaussNewton(obs, best, 0.0, 1, &at, &H)) {
    double rr = 0;
    Eigen::Vector2d r;
    for (int i : best)
      if (poseResidual(fit.R, fit.t, obs[i], &r)) rr += obs[i].weight * r.squaredNorm();
    const double sigma2 = rr / std::max(1.0, 2.0 * best.size() - 6);
    cov_t = sigma2 * H.inverse().bottomRightCorner<3, 3>();
  }

  // Held out: halves of whole groups (frame pairs) when there are several,
  // else alternate matches, each fitted alone. A translation error moves a
  // residual by a small fraction of its noise (3 mm at 15 m: 0.01 deg against
  // 0.05 deg), so the halves are compared by what they say of the
  // translation: each must move it the same way as the whole fit, by at
  // least a third of the whole's change. (The other half's weighted residual
  // at each half's fit, over its inliers at the current pose, is reported:
  // it moves by less than its noise for a few millimetres.)
  std::vector<int> ids;
  for (const PoseObs& o : obs) ids.push_back(o.group);
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  std::vector<int> half[2];
  for (int i = 0; i < int(obs.size()); ++i) {
    const int rank = int(std::lower_bound(ids.begin(), ids.end(), obs[i].group) - ids.begin());
    half[ids.size() >= 2 ? rank % 2 : i % 2].push_back(i);
  }
  const auto weightedRms = [&](const std::vector<int>& idx, const PoseFit& f) {
    double sw = 0, s2 = 0;
    Eigen::Vector2d r;
    for (int i : idx)
      if (poseResidual(f.R, f.t, obs[i], &r)) sw += obs[i].weight, s2 += obs[i].weight * r.squaredNorm();
    return sw > 0 ? std::sqrt(s2 / sw) : 0.0;
  };
  double before = 0, after = 0;
  bool agree = true;
  const double d2 = dt.squaredNorm();
  Eigen::Vector3d t_half[2];
  for (int k = 0; k < 2; ++k) {
    PoseFit fk = cur;
    robustPoseFit(obs, half[k], config, &fk);
    t_half[k] = fk.t;
    const std::vector<int> other = poseInliers(obs, half[1 - k], cur, thr);
    const double b = weightedRms(other, cur), a = weightedRms(other, fk);
    before += 0.5 * b, after += 0.5 * a;
    const double along = d2 > 0 ? (fk.t - cur.t).dot(dt) / d2 : 0.0;
    if (!(along > 1.0 / 3.0)) agree = false;
  }
  out.heldout_before_deg = before / kDeg;
  out.heldout_after_deg = after / kDeg;
  // The residuals' spread understates the translation's error when errors
  // are shared within a frame pair (one scene, one motion): the halves' fits
  // then differ by more than their covariance (about twice the whole's each)
  // allows, and the whole's covariance is scaled up by that excess.
  if (cov_t.allFinite()) {
    const Eigen::Vector3d d = t_half[0] - t_half[1];
    const Eigen::LDLT<Eigen::Matrix3d> pair(4.0 * cov_t);
    if (pair.info() == Eigen::Success) {
      const double excess = d.dot(pair.solve(d)) / 3.0;
      if (excess > 1.0) cov_t *= excess;
    }
    const Eigen::LDLT<Eigen::Matrix3d> ldlt(cov_t);
    if (ldlt.info() == Eigen::Success && dt.norm() > 0) sig = std::sqrt(std::max(0.0, dt.dot(ldlt.solve(dt))));
  }
  out.translation_standard_error_mm = sig > 0 ? out.translation_change_mm / sig : INFINITY;
  std::ostringstream why;
  why.precision(4);
  if (!agree) {
    out.status = CameraRefinement::Status::kNotImproved;
    why << "the halves' fits do not move the translation the same way (held-out residual " << out.heldout_before_deg
        << " -> " << out.heldout_after_deg << " deg)";
    out.message = why.str();
    return out;
  }
  if (sig < config.min_significance) {
    out.status = CameraRefinement::Status::kNotImproved;
    why << "translation change " << out.translation_change_mm << " mm is within " << config.min_significance
        << " standard errors (" << out.translation_standard_error_mm << " mm)";
    out.message = why.str();
    return out;
  }
  out.status = CameraRefinement::Status::kApplied;
  Eigen::Isometry3d T_new = Eigen::Isometry3d::Identity();
  T_new.linear() = fit.R;
  T_new.translation() = fit.t;
  *T_estimated = T_new;
  return out;
}

void compareTranslations(const std::vector<EpipolarMatch>& matches, const Eigen::Matrix3d& R0,
                         const Eigen::Vector3d& t_a, const Eigen::Vector3d& t_b, const RigRefinementConfig& config,
                         double* rms_a_deg, double* rms_b_deg) {
  require(t_a.norm() > 1e-6 && t_b.norm() > 1e-6, "translation", "has no baseline");
  const Eigen::Vector3d da = t_a.normalized();
  std::vector<Match> cand;
  for (const Match& m : matches)
    if (m.f_ref.allFinite() && m.f_cam.allFinite() && m.weight > 0 &&
        std::abs(EpipolarModel::residual(R0, da, m)) < config.max_initial_residual_deg * kDeg)
      cand.push_back(m);
  keepEvenSubsample(&cand, config.max_fit_matches);
  normalizeWeights(&cand);
  std::vector<int> all(cand.size());
  std::iota(all.begin(), all.end(), 0);
  const double tau = config.heldout_truncation_deg * kDeg;
  const auto score = [&](const Eigen::Vector3d& t) {
    const EpipolarModel model(R0, t, false);
    Eigen::VectorXd x = Eigen::VectorXd::Zero(3);
    Eigen::VectorXd xr = x;
    if (gaussNewton(model, cand, all, config.huber_deg * kDeg, config.max_iterations, &xr)) x = xr;
    return truncatedRms(model, cand, all, x, tau) / kDeg;
  };
  *rms_a_deg = score(t_a);
  *rms_b_deg = score(t_b);
}

RigRefinementResult refineRig(const Rig& rig, int reference, const std::vector<std::vector<cv::Mat>>& frame_sets,
                              const std::vector<cv::Mat>& self_masks, const RigRefinementConfig& config) {
  config.validate();
  const int n_cams = int(rig.cameras.size());
  require(n_cams >= 2, "rig", "needs at least two cameras, has " + std::to_string(n_cams));
  require(reference >= 0 && reference < n_cams, "reference",
          "camera index " + std::to_string(reference) + " is not in [0, " + std::to_string(n_cams) + ")");
  require(!frame_sets.empty(), "frame_sets", "no frame set given");
  for (size_t k = 0; k < frame_sets.size(); ++k) {
    const std::string where = "frame set " + std::to_string(k);
    require(int(frame_sets[k].size()) == n_cams, where,
            "has " + std::to_string(frame_sets[k].size()) + " images, the rig has " + std::to_string(n_cams) +
                " cameras");
    for (int c = 0; c < n_cams; ++c) {
      const cv::Mat& im = frame_sets[k][c];
      const RigCamera& cam = rig.cameras[c];
      require(!im.empty(), where + ", " + cam.name, "image is empty");
      require(im.type() == CV_8UC1, where + ", " + cam.name, "image must be 8-bit single-channel (CV_8UC1)");
      require(im.cols == cam.model.width() && im.rows == cam.model.height(), where + ", " + cam.name,
              "image is " + sizeText(im) + ", calibration says " + std::to_string(cam.model.width()) + "x" +
                  std::to_string(cam.model.height()));
    }
  }
  require(self_masks.empty() || int(self_masks.size()) == n_cams, "self_masks",
          "need none or one per camera (" + std::to_string(n_cams) + "), got " + std::to_string(self_masks.size()));
  for (int c = 0; c < n_cams && !self_masks.empty(); ++c) {
    const cv::Mat& m = self_masks[c];
    const RigCamera& cam = rig.cameras[c];
    if (m.empty()) continue;
    require(m.type() == CV_8UC1, "self-mask of " + cam.name, "must be 8-bit single-channel (CV_8UC1)");
    require(m.cols == cam.model.width() && m.rows == cam.model.height(), "self-mask of " + cam.name,
            "is " + sizeText(m) + ", calibration says " + std::to_string(cam.model.width()) + "x" +
                std::to_string(cam.model.height()));
  }
  RigRefinementResult result;
  result.rig = rig;
  result.frame_sets = int(frame_sets.size());
  result.cameras.resize(n_cams);
  for (int c = 0; c < n_cams; ++c) {
    result.cameras[c].camera = c;
    result.cameras[c].name = rig.cameras[c].name;
  }
  // Matches per support camera, pooled over the frame sets.
  RigMatcher matcher(config, self_masks);
  std::vector<std::vector<Match>> pooled(n_cams);
  std::vector<std::vector<int>> groups(n_cams);  // the frame set of each match
  std::vector<int> raw_matches(n_cams, 0);
  for (size_t k = 0; k < frame_sets.size(); ++k) {
    std::vector<int> raw;
    const auto found = matcher.match(rig, reference, frame_sets[k], &raw);
    for (int c = 0; c < n_cams; ++c) {
      pooled[c].insert(pooled[c].end(), found[c].begin(), found[c].end());
      groups[c].insert(groups[c].end(), found[c].size(), int(k));
      raw_matches[c] += raw[c];
    }
  }
  std::mt19937_64 rng(config.seed);
  const Eigen::Isometry3d T_base_ref = rig.cameras[reference].T_base_cam;
  for (int c = 0; c < n_cams; ++c) {
    if (c == reference) continue;
    Eigen::Isometry3d T_new;
    CameraRefinement r =
        estimateCameraCorrection(pooled[c], T_base_ref.inverse() * rig.cameras[c].T_base_cam, config, rng, &T_new,
                                 groups[c]);
    r.camera = c;
    r.name = rig.cameras[c].name;
    r.matches = raw_matches[c];
    if (r.status == CameraRefinement::Status::kApplied) result.rig = withRelativePose(result.rig, reference, c, T_new);
    result.cameras[c] = r;
  }
  return result;
}

}  // namespace fisheye_mapping
