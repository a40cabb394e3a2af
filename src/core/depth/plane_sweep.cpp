#include "fisheye_mapping/core/depth/plane_sweep.h"

#include "fisheye_mapping/core/common/opencl_context.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <stdexcept>

#include <opencv2/imgproc.hpp>
#include <opencv2/imgcodecs.hpp>

namespace fisheye_mapping {
namespace {

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

void require(bool ok, const std::string& field, const std::string& what) {
  if (!ok) throw std::invalid_argument(field + ": " + what);
}

FmViewPose toViewPose(const Eigen::Isometry3d& T_view_ref) {
  FmViewPose p{};
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) p.r[3 * r + c] = static_cast<float>(T_view_ref.linear()(r, c));
    p.t[r] = static_cast<float>(T_view_ref.translation()[r]);
  }
  return p;
}

// Nearest-neighbour upsampling of a half-resolution map to width x height.
cv::Mat upsampleNearest(const cv::Mat& half, int width, int height) {
  cv::Mat out(height, width, CV_32FC1, cv::Scalar(NAN));
  for (int v = 0; v < height; ++v) {
    const int hv = std::min(v / 2, half.rows - 1);
    const float* src = half.ptr<float>(hv);
    float* dst = out.ptr<float>(v);
    for (int u = 0; u < width; ++u) dst[u] = src[std::min(u / 2, half.cols - 1)];
  }
  return out;
}

// Throws "<view>: <what> is WxH, calibration says WxH" on a size mismatch.
void checkSize(const SweepView& view, const cv::Mat& m, const char* what) {
  if (m.cols == view.camera.width() && m.rows == view.camera.height()) return;
  std::ostringstream os;
  os << view.name << ": " << what << " is " << m.cols << "x" << m.rows << ", calibration says " << view.camera.width()
     << "x" << view.camera.height();
  throw std::invalid_argument(os.str());
}

cv::Mat checkedMask(const SweepView& view) {
  if (view.mask.empty()) return cv::Mat::zeros(view.camera.height(), view.camera.width(), CV_8UC1);
  if (view.mask.type() != CV_8UC1) {
    throw std::invalid_argument(view.name + ": self-mask must be an 8-bit single-channel image");
  }
  checkSize(view, view.mask, "self-mask");
  return view.mask;
}

// 255 where a float image is NaN or infinite (empty for other types); throws
// when no pixel is finite.
cv::Mat nonFinite(const SweepView& view, std::vector<std::string>* warnings) {
  if (view.image.type() != CV_32FC1) return cv::Mat();
  cv::Mat finite = (view.image == view.image) & (cv::abs(view.image) < std::numeric_limits<float>::infinity());
  const int bad = static_cast<int>(view.image.total()) - cv::countNonZero(finite);
  if (bad == static_cast<int>(view.image.total())) {
    throw std::invalid_argument(view.name + ": image has no finite pixel (all NaN or infinite)");
  }
  if (bad > 0 && warnings) {
    warnings->push_back(view.name + ": " + std::to_string(bad) + " non-finite pixels (NaN or infinite) treated as masked");
  }
  return finite == 0;
}

// The view's self-mask with its non-finite pixels added.
cv::Mat maskWithNonFinite(const cv::Mat& mask, const SweepView& view, std::vector<std::string>* warnings) {
  const cv::Mat bad = nonFinite(view, warnings);
  return bad.empty() ? mask : cv::Mat(mask | bad);
}

void checkImage(const SweepView& view) {
  if (view.image.empty()) throw std::invalid_argument(view.name + ": empty image");
  const int t = view.image.type();
  if (t != CV_8UC1 && t != CV_8UC3 && t != CV_8UC4 && t != CV_16UC1 && t != CV_32FC1) {
    throw std::invalid_argument(view.name + ": unsupported image type (expected 8-bit grey/BGR/BGRA, 16-bit grey or float)");
  }
  checkSize(view, view.image, "image");
}

// Window mean and standard deviation of a float image.
void windowStats(const cv::Mat& img, int radius, cv::Mat* mean, cv::Mat* stddev) {
  const cv::Size k(2 * radius + 1, 2 * radius + 1);
  cv::Mat sq;
  cv::boxFilter(img, *mean, CV_32F, k, cv::Point(-1, -1), true, cv::BORDER_REPLICATE);
  cv::boxFilter(img.mul(img), sq, CV_32F, k, cv::Point(-1, -1), true, cv::BORDER_REPLICATE);
  *stddev = sq - mean->mul(*mean);
  cv::max(*stddev, 0.0, *stddev);
  cv::sqrt(*stddev, *stddev);
}

}  // namespace

SweepAggregation parseSweepAggregation(const std::string& s) {
  if (s == "average") return SweepAggregation::Average;
  if (s == "best_k") return SweepAggregation::BestK;
  throw std::invalid_argument("aggregation: must be 'average' or 'best_k', got '" + s + "'");
}

SweepResolution parseSweepResolution(const std::string& s) {
  if (s == "full") return SweepResolution::Full;
  if (s == "half") return SweepResolution::Half;
  if (s == "multiscale") return SweepResolution::Multiscale;
  throw std::invalid_argument("resolution: must be 'full', 'half' or 'multiscale', got '" + s + "'");
}

SweepBackendType parseSweepBackend(const std::string& s) {
  if (s == "auto") return SweepBackendType::Auto;
  if (s == "native") return SweepBackendType::Native;
  if (s == "opencl") return SweepBackendType::OpenCl;
  if (s == "cpu") return SweepBackendType::Cpu;
  throw std::invalid_argument("backend: must be 'auto', 'native', 'opencl' or 'cpu', got '" + s + "'");
}

std::string toString(SweepAggregation a) {
  switch (a) {
    case SweepAggregation::Average: return "average";
    case SweepAggregation::BestK: return "best_k";
  }
  return "?";
}

std::string toString(SweepResolution r) {
  switch (r) {
    case SweepResolution::Full: return "full";
    case SweepResolution::Half: return "half";
    case SweepResolution::Multiscale: return "multiscale";
  }
  return "?";
}

std::string toString(SweepBackendType b) {
  switch (b) {
    case SweepBackendType::Auto: return "auto";
    case SweepBackendType::Native: return "native";
    case SweepBackendType::OpenCl: return "opencl";
    case SweepBackendType::Cpu: return "cpu";
  }
  return "?";
}

void DepthFilterConfig::validate() const {
  require(std::isfinite(min_texture_snr) && min_texture_snr >= 0, "filters.min_texture_snr", "must be >= 0");
  require(std::isfinite(min_noise_std) && min_noise_std > 0, "filters.min_noise_std", "must be positive");
  require(alpha_upper >= 0 && alpha_upper <= 1, "filters.alpha_upper", "must be in [0, 1]");
  require(alpha_lower >= 0 && alpha_lower <= 1, "filters.alpha_lower", "must be in [0, 1]");
  require(split_row >= 0 && split_row <= 1, "filters.split_row", "must be in [0, 1]");
  require(max_ratio > 0 && max_ratio <= 1, "filters.max_ratio", "must be in (0, 1]");
  require(consistency_window >= 3 && consistency_window % 2 == 1, "filters.consistency_window",
          "must be odd and >= 3");
  require(gamma > 0, "filters.gamma", "must be positive");
  require(delta >= 0 && delta <= 1, "filters.delta", "must be in [0, 1]");
}

void PlaneSweepConfig::validate() const {
  require(fronto_planes >= 2, "fronto_planes", "must be at least 2");
  require(ground_planes == 0 || ground_planes >= 2, "ground_planes", "must be 0 or at least 2");
  require(std::isfinite(near) && near > 0, "near", "must be positive");
  require(std::isfinite(far) && far > near, "far", "must be greater than near");
  require(std::isfinite(ground_min) && std::isfinite(ground_max) && ground_max > ground_min, "ground_max",
          "must be greater than ground_min");
  require(std::isfinite(ground_height), "ground_height", "must be a finite number of metres");
  require(window_full >= 3 && window_full % 2 == 1, "window_full", "must be odd and >= 3");
  require(window_half >= 3 && window_half % 2 == 1, "window_half", "must be odd and >= 3");
  require(aggregation == SweepAggregation::Average || aggregation == SweepAggregation::BestK, "aggregation",
          "must be 'average' or 'best_k', got " + std::to_string(static_cast<int>(aggregation)));
  require(best_k >= 1, "best_k", "must be at least 1");
  require(resolution == SweepResolution::Full || resolution == SweepResolution::Half ||
              resolution == SweepResolution::Multiscale,
          "resolution", "must be 'full', 'half' or 'multiscale', got " + std::to_string(static_cast<int>(resolution)));
  require(crop_width > 0 && crop_width <= 1, "crop_width", "must be in (0, 1]");
  require(crop_height > 0 && crop_height <= 1, "crop_height", "must be in (0, 1]");
  require(min_parallax_px >= 0, "min_parallax_px", "must be >= 0");
  require(min_parallax_ratio >= 0 && min_parallax_ratio <= 1, "min_parallax_ratio", "must be in [0, 1]");
  require(min_overlap >= 0 && min_overlap <= 1, "min_overlap", "must be in [0, 1]");
  require(backend == SweepBackendType::Auto || backend == SweepBackendType::Native ||
              backend == SweepBackendType::OpenCl || backend == SweepBackendType::Cpu,
          "backend", "must be 'auto', 'native', 'opencl' or 'cpu', got " + std::to_string(static_cast<int>(backend)));
  require(band_rows >= 1, "band_rows", "must be at least 1");
  filters.validate();
}

std::vector<FmSweepPlane> makeSweepPlanes(const PlaneSweepConfig& config, const Eigen::Isometry3d* T_base_ref) {
  std::vector<FmSweepPlane> planes;
  // Fronto-parallel: uniform in inverse depth, near to far.
  const double inv_near = 1.0 / config.near, inv_far = 1.0 / config.far;
  for (int i = 0; i < config.fronto_planes; ++i) {
    const double s = inv_near + (inv_far - inv_near) * i / (config.fronto_planes - 1);
    FmSweepPlane p{};
    p.nx = 0.0f;
    p.ny = 0.0f;
    p.nz = 1.0f;
    p.d = static_cast<float>(1.0 / s);
    p.family = FM_FAMILY_FRONTO;
    planes.push_back(p);
  }
  if (T_base_ref && config.ground_planes > 0) {
    // Plane z_base = h: e_z . (R X_ref + t) = h, i.e. n . X_ref = d with
    // n = -R^T e_z (pointing down, towards the ground) and d = t_z - h.
    const Eigen::Vector3d n = -(T_base_ref->linear().transpose() * Eigen::Vector3d::UnitZ());
    const double tz = T_base_ref->translation().z();
    for (int i = 0; i < config.ground_planes; ++i) {
      const double h = config.ground_height + config.ground_min +
                       (config.ground_max - config.ground_min) * i / (config.ground_planes - 1);
      const double d = tz - h;
      if (!(d > 0.0)) continue;  // plane at or above the camera: never seen from above
      FmSweepPlane p{};
      p.nx = static_cast<float>(n.x());
      p.ny = static_cast<float>(n.y());
      p.nz = static_cast<float>(n.z());
      p.d = static_cast<float>(d);
      p.family = FM_FAMILY_GROUND;
      planes.push_back(p);
    }
  }
  return planes;
}

cv::Mat toSweepImage(const cv::Mat& image, const std::string& what) {
  cv::Mat grey;
  switch (image.type()) {
    case CV_8UC1:
      image.convertTo(grey, CV_32F, 1.0 / 255.0);
      break;
    case CV_8UC3:
      cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
      grey.convertTo(grey, CV_32F, 1.0 / 255.0);
      break;
    case CV_8UC4:
      cv::cvtColor(image, grey, cv::COLOR_BGRA2GRAY);
      grey.convertTo(grey, CV_32F, 1.0 / 255.0);
      break;
    case CV_16UC1:
      image.convertTo(grey, CV_32F, 1.0 / 65535.0);
      break;
    case CV_32FC1:
      grey = image.clone();
      // NaN and +-inf to 0 (compute() masks them): one infinite pixel would
      // poison every window sum it slides through.
      grey.setTo(0.0f, ~((grey == grey) & (cv::abs(grey) < std::numeric_limits<float>::infinity())));
      break;
    default:
      throw std::invalid_argument(what + ": unsupported image type (expected 8-bit grey/BGR/BGRA, 16-bit grey or float)");
  }
  return grey;
}

double estimateNoiseStd(const cv::Mat& image, const cv::Mat& valid) {
  CV_Assert(image.type() == CV_32FC1 && (valid.empty() || (valid.type() == CV_8UC1 && valid.size() == image.size())));
  // Immerkaer (1996): N = [1 -2 1; -2 4 -2; 1 -2 1] has zero response to
  // planar intensity; on white noise of std s its response has std 6 s, and
  // a normal variable's median absolute value is 0.6745 std.
  std::vector<float> r;
  r.reserve(static_cast<size_t>(image.rows) * image.cols / 2);
  for (int v = 1; v + 1 < image.rows; ++v) {
    const float* a = image.ptr<float>(v - 1);
    const float* b = image.ptr<float>(v);
    const float* c = image.ptr<float>(v + 1);
    const uint8_t* ma = valid.empty() ? nullptr : valid.ptr<uint8_t>(v - 1);
    const uint8_t* mb = valid.empty() ? nullptr : valid.ptr<uint8_t>(v);
    const uint8_t* mc = valid.empty() ? nullptr : valid.ptr<uint8_t>(v + 1);
    for (int u = 1; u + 1 < image.cols; ++u) {
      if (ma && !(ma[u - 1] && ma[u] && ma[u + 1] && mb[u - 1] && mb[u] && mb[u + 1] && mc[u - 1] && mc[u] && mc[u + 1])) {
        continue;
      }
      const float n = a[u - 1] - 2 * a[u] + a[u + 1] - 2 * (b[u - 1] - 2 * b[u] + b[u + 1]) + c[u - 1] - 2 * c[u] + c[u + 1];
      r.push_back(std::fabs(n));
    }
  }
  if (r.empty()) return 0.0;
  // The lower quartile: texture and edges add to the upper part of the
  // distribution. |N(0, 1)|'s quartile is 0.3186.
  std::nth_element(r.begin(), r.begin() + r.size() / 4, r.end());
  return r[r.size() / 4] / (0.3186 * 6.0);
}

cv::Mat texturelessRegions(const cv::Mat& image, const cv::Mat& valid, double min_snr, double min_noise_std,
                           int window) {
  CV_Assert(image.type() == CV_32FC1 && valid.type() == CV_8UC1 && valid.size() == image.size() && window >= 3);
  const double noise = std::max(estimateNoiseStd(image, valid), min_noise_std);
  const double floor2 = min_snr * noise * min_snr * noise;
  auto variance = [&](int size) {
    cv::Mat mean, sq;
    cv::boxFilter(image, mean, CV_32F, cv::Size(size, size), cv::Point(-1, -1), true, cv::BORDER_REPLICATE);
    cv::boxFilter(image.mul(image), sq, CV_32F, cv::Size(size, size), cv::Point(-1, -1), true, cv::BORDER_REPLICATE);
    return cv::Mat(sq - mean.mul(mean));
  };
  const cv::Mat var3 = variance(3), var_window = variance(window);
  cv::Mat flat = (var3 < floor2) & (valid != 0);
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(flat, labels, stats, centroids, 4, CV_32S);
  // A region flat at 3x3 three quarters of whose windows are flat too (sky,
  // a blank wall; a road's texture shows at the window's scale: measured on
  // synthetic drives, sky regions 0.89-0.95 of their windows flat, roads and
  // sidewalks 0.45-0.66), at least 0.2 % of the valid pixels.
  std::vector<int> flat_windows(n, 0);
  for (int v = 0; v < image.rows; ++v) {
    const int* l = labels.ptr<int>(v);
    const float* w = var_window.ptr<float>(v);
    for (int u = 0; u < image.cols; ++u) {
      if (l[u] > 0 && w[u] < floor2) ++flat_windows[l[u]];
    }
  }
  const int min_area = std::max(1, static_cast<int>(0.002 * cv::countNonZero(valid)));
  std::vector<uint8_t> textureless(n, 0);
  for (int i = 1; i < n; ++i) {
    const int area = stats.at<int>(i, cv::CC_STAT_AREA);
    textureless[i] = (area >= min_area && 4 * flat_windows[i] >= 3 * area) ? 255 : 0;
  }
  cv::Mat region(image.size(), CV_8UC1);
  for (int v = 0; v < image.rows; ++v) {
    const int* l = labels.ptr<int>(v);
    uint8_t* r = region.ptr<uint8_t>(v);
    for (int u = 0; u < image.cols; ++u) r[u] = textureless[l[u]];
  }
  cv::dilate(region, region, cv::Mat::ones(5, 5, CV_8UC1));
  return region;
}

cv::Mat applyDepthFilters(const DepthFilterConfig& config, const cv::Mat& raw, const cv::Mat& cost,
                          const cv::Mat& ratio, const cv::Mat& texture) {
  cv::Mat depth = raw.clone();
  const int w = raw.cols, h = raw.rows;
  const int split = static_cast<int>(std::lround(config.split_row * h));
  const bool use_texture = config.texture && !texture.empty();
  const float min_snr = static_cast<float>(config.min_texture_snr);
  for (int v = 0; v < h; ++v) {
    float* d = depth.ptr<float>(v);
    const float* c = cost.ptr<float>(v);
    const float* q = ratio.ptr<float>(v);
    const float* t = use_texture ? texture.ptr<float>(v) : nullptr;
    const float alpha = static_cast<float>(v < split ? config.alpha_upper : config.alpha_lower);
    for (int u = 0; u < w; ++u) {
      if (t && !(t[u] >= min_snr)) d[u] = NAN;
      if (config.cost && !(c[u] <= alpha)) d[u] = NAN;
      if (config.uniqueness && !(q[u] <= config.max_ratio)) d[u] = NAN;
    }
  }
  if (!config.consistency) return depth;
  const cv::Mat in = depth.clone();
  const int r = config.consistency_window / 2;
  const int others = config.consistency_window * config.consistency_window - 1;
  const float gamma = static_cast<float>(config.gamma);
#pragma omp parallel for schedule(static)
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const float d = in.at<float>(v, u);
      if (!std::isfinite(d)) continue;
      int consistent = 0;
      for (int y = std::max(0, v - r); y <= std::min(h - 1, v + r); ++y) {
        const float* row = in.ptr<float>(y);
        for (int x = std::max(0, u - r); x <= std::min(w - 1, u + r); ++x) {
          if ((x != u || y != v) && std::fabs(row[x] - d) < gamma) ++consistent;  // NaN compares false
        }
      }
      if (consistent < config.delta * others) depth.at<float>(v, u) = NAN;
    }
  }
  return depth;
}

std::vector<int> selectSupportViews(const PlaneSweepConfig& config, const CameraModel& ref,
                                    const std::vector<SweepView>& views, std::vector<std::string>* reasons) {
  // Reference pixels on a coarse grid, with the angle one pixel spans there.
  std::vector<Eigen::Vector3d> rays;
  std::vector<double> pixel_angle;
  for (int gy = 1; gy < 12; ++gy) {
    for (int gx = 1; gx < 16; ++gx) {
      const Eigen::Vector2d px(ref.width() * gx / 16.0, ref.height() * gy / 12.0);
      Eigen::Vector3d ray, next;
      if (ref.unproject(px, &ray) && ray.z() > 0.1 && ref.unproject(px + Eigen::Vector2d(1.0, 0.0), &next)) {
        rays.push_back(ray.normalized());
        pixel_angle.push_back(std::max(1e-9, std::acos(std::clamp(ray.normalized().dot(next.normalized()), -1.0, 1.0))));
      }
    }
  }
  const double mid = std::sqrt(config.near * config.far);
  std::vector<double> overlaps, per_plane;
  for (size_t i = 0; i < views.size(); ++i) {
    const SweepView& view = views[i];
    const Eigen::Isometry3d T_view_ref = view.T_ref_view.inverse();
    std::vector<double> parallax;
    int seen = 0;
    for (size_t k = 0; k < rays.size(); ++k) {
      const Eigen::Vector3d& ray = rays[k];
      Eigen::Vector2d a, b, m;
      // Fronto-parallel planes: z-depth near / far / mid along the ray.
      const Eigen::Vector3d pn = T_view_ref * (ray * (config.near / ray.z()));
      const Eigen::Vector3d pf = T_view_ref * (ray * (config.far / ray.z()));
      const bool pa = view.camera.project(pn, &a) && view.camera.isInImage(a);
      const bool pb = view.camera.project(pf, &b) && view.camera.isInImage(b);
      if (view.camera.project(T_view_ref * (ray * (mid / ray.z())), &m) && view.camera.isInImage(m)) ++seen;
      if (!(pa && pb)) continue;
      // In pixels of the coarser of the two images: a view with a longer
      // focal length (a narrow camera) has many of its own pixels of
      // parallax where the reference's window cannot resolve it.
      const double angle = std::acos(std::clamp(pn.normalized().dot(pf.normalized()), -1.0, 1.0));
      parallax.push_back(std::min((a - b).norm(), angle / pixel_angle[k]));
    }
    const double overlap = rays.empty() ? 0.0 : static_cast<double>(seen) / rays.size();
    double median = 0.0;
    if (!parallax.empty()) {
      std::nth_element(parallax.begin(), parallax.begin() + parallax.size() / 2, parallax.end());
      median = parallax[parallax.size() / 2];
    }
    overlaps.push_back(overlap);
    per_plane.push_back(median / std::max(1, config.fronto_planes - 1));
  }
  // The views that overlap enough; the largest parallax among them.
  double best = 0.0;
  for (size_t i = 0; i < views.size(); ++i) {
    if (overlaps[i] >= config.min_overlap) best = std::max(best, per_plane[i]);
  }
  std::vector<int> keep;
  for (size_t i = 0; i < views.size(); ++i) {
    std::ostringstream why;
    why.precision(3);
    if (overlaps[i] < config.min_overlap) {
      why << views[i].name << ": overlap " << overlaps[i] << " < min_overlap " << config.min_overlap;
    } else if (per_plane[i] < config.min_parallax_px) {
      why << views[i].name << ": parallax " << per_plane[i] << " px per plane < min_parallax_px "
          << config.min_parallax_px << " (baseline too small for the depth range)";
    } else if (per_plane[i] < config.min_parallax_ratio * best) {
      why << views[i].name << ": parallax " << per_plane[i] << " px per plane < min_parallax_ratio "
          << config.min_parallax_ratio << " x " << best
          << " of the best view (its cost curve is too flat to sharpen the mean; it would add noise and its "
             "calibration error)";
    } else {
      keep.push_back(static_cast<int>(i));
      continue;
    }
    if (reasons) reasons->push_back(why.str());
  }
  return keep;
}

SweepView rigSweepView(const Rig& rig, int index, int ref_index, const cv::Mat& image, const cv::Mat& mask) {
  const RigCamera& cam = rig.cameras.at(index);
  const RigCamera& ref = rig.cameras.at(ref_index);
  SweepView view;
  view.name = cam.name;
  view.camera = cam.model;
  view.T_ref_view = ref.T_cam0_cam.inverse() * cam.T_cam0_cam;
  view.image = image;
  view.mask = mask;
  return view;
}

// ---------------------------------------------------------------------------

PlaneSweep::PlaneSweep(const PlaneSweepConfig& config) : config_(config) {
  config_.validate();
  SweepBackendType backend = config_.backend;
  if (backend == SweepBackendType::Auto)
    backend = (!config_.device.empty() || OpenClContext::hasGpu()) ? SweepBackendType::OpenCl : SweepBackendType::Native;
  if (backend == SweepBackendType::Cpu) {
    backend_ = makeCpuSweepBackend();
  } else if (backend == SweepBackendType::Native) {
    backend_ = makeNativeSweepBackend();
  } else {
    backend_ = makeOpenClSweepBackend(config_.device);
  }
}

PlaneSweep::~PlaneSweep() = default;

std::string PlaneSweep::backendName() const { return backend_->name(); }

void PlaneSweep::setFilters(const DepthFilterConfig& filters) {
  filters.validate();
  config_.filters = filters;
}

const std::vector<float>& PlaneSweep::raysFor(int slot, const CameraModel& camera, const cv::Mat& mask,
                                              unsigned* version) {
  RayCache& cache = rays_[slot];
  const FmCameraT<float> params = camera.floatParams();
  const bool same_mask = !cache.mask.empty() && cache.mask.size() == mask.size() &&
                         cv::countNonZero(cache.mask != mask) == 0;
  if (cache.rays.empty() || std::memcmp(&params, &cache.camera, sizeof(params)) != 0 || !same_mask) {
    const std::vector<Eigen::Vector3f> rays = pixelRays(camera);
    cache.rays.assign(3 * rays.size(), 0.0f);
    cache.valid = cv::Mat::zeros(camera.height(), camera.width(), CV_8UC1);
    for (size_t i = 0; i < rays.size(); ++i) {
      if (!rays[i].allFinite() || mask.data[i] != 0) continue;
      for (int a = 0; a < 3; ++a) cache.rays[3 * i + a] = rays[i][a];
      cache.valid.data[i] = 255;
    }
    cache.camera = params;
    cache.mask = mask.clone();
    ++cache.version;
  }
  *version = cache.version;
  return cache.rays;
}

DepthResult PlaneSweep::compute(const SweepView& ref, const std::vector<SweepView>& supports,
                                const Eigen::Isometry3d* T_base_ref) {
  const auto t0 = std::chrono::steady_clock::now();
  checkImage(ref);
  for (const auto& s : supports) {
    checkImage(s);
    checkedMask(s);
  }
  DepthResult result;
  const cv::Mat ref_mask = maskWithNonFinite(checkedMask(ref), ref, &result.warnings);
  std::vector<int> used = selectSupportViews(config_, ref.camera, supports, &result.dropped_views);
  if (used.size() > FM_SWEEP_MAX_VIEWS) {
    throw std::invalid_argument("too many supporting views: " + std::to_string(used.size()) + " > " +
                                std::to_string(FM_SWEEP_MAX_VIEWS));
  }
  for (int i : used) result.used_views.push_back(supports[i].name);
  const int W = ref.camera.width(), H = ref.camera.height();
  result.raw_depth = cv::Mat(H, W, CV_32FC1, cv::Scalar(NAN));
  result.cost = cv::Mat(H, W, CV_32FC1, cv::Scalar(NAN));
  result.uniqueness = cv::Mat(H, W, CV_32FC1, cv::Scalar(NAN));
  if (!used.empty()) {
    const std::vector<FmSweepPlane> planes = makeSweepPlanes(config_, T_base_ref);
    const cv::Mat ref_full = toSweepImage(ref.image, ref.name);
    std::vector<cv::Mat> img_full, mask_full;
    for (int i : used) {
      img_full.push_back(toSweepImage(supports[i].image, supports[i].name));
      mask_full.push_back(maskWithNonFinite(checkedMask(supports[i]), supports[i], &result.warnings));
    }
    // One scale: slot 0 full view, 1 half view, 2 full-resolution crop.
    auto run = [&](int slot, cv::Mat* range, cv::Mat* cost, cv::Mat* ratio, cv::Mat* texture) {
      SweepLevel level;
      level.id = slot;
      CameraModel cam = ref.camera;
      cv::Mat ref_img = ref_full, rmask = ref_mask;
      const bool half = slot == 1;
      if (half) {
        const int hw = W / 2, hh = H / 2;
        cam = ref.camera.scaled(0.5, hw, hh);
        cv::resize(ref_full, ref_img, cv::Size(hw, hh), 0, 0, cv::INTER_AREA);
        cv::resize(ref_mask, rmask, cv::Size(hw, hh), 0, 0, cv::INTER_AREA);
        rmask = rmask != 0;  // any masked pixel under a half-resolution pixel masks it
      } else if (slot == 2) {
        const int cw = std::min(W, static_cast<int>(std::lround(config_.crop_width * W)));
        const int ch = std::min(H, static_cast<int>(std::lround(config_.crop_height * H)));
        const int x0 = std::clamp(static_cast<int>(std::lround(ref.camera.params().cx + 0.5 - cw / 2.0)), 0, W - cw);
        const int y0 = std::clamp(static_cast<int>(std::lround(ref.camera.params().cy + 0.5 - ch / 2.0)), 0, H - ch);
        cam = ref.camera.cropped(x0, y0, cw, ch);
        const cv::Rect roi(x0, y0, cw, ch);
        ref_img = ref_full(roi).clone();
        rmask = ref_mask(roi).clone();
      }
      level.rays = &raysFor(slot, cam, rmask, &level.rays_version);
      level.width = cam.width();
      level.height = cam.height();
      level.ref = ref_img;
      level.radius = (half ? config_.window_half : config_.window_full) / 2;
      windowStats(ref_img, level.radius, &level.ref_mean, &level.ref_std);
      // Texture against this scale's own noise (averaging to half resolution
      // halves it), over the pixels with a ray that is not masked.
      const cv::Mat& valid = rays_[slot].valid;
      const double noise = std::max(estimateNoiseStd(ref_img, valid), config_.filters.min_noise_std);
      level.ref_std.convertTo(*texture, CV_32F, 1.0 / noise);
      texture->setTo(NAN, valid == 0);
      for (size_t k = 0; k < used.size(); ++k) {
        const SweepView& s = supports[used[k]];
        const Eigen::Isometry3d T_view_ref = s.T_ref_view.inverse();
        if (half) {
          const int sw = s.camera.width() / 2, sh = s.camera.height() / 2;
          level.cameras.push_back(s.camera.scaled(0.5, sw, sh).floatParams());
          cv::Mat im, mk;
          cv::resize(img_full[k], im, cv::Size(sw, sh), 0, 0, cv::INTER_AREA);
          cv::resize(mask_full[k], mk, cv::Size(sw, sh), 0, 0, cv::INTER_AREA);
          im.setTo(-1.0f, mk != 0);  // any masked pixel under a half-resolution pixel masks it
          level.images.push_back(im);
        } else {
          level.cameras.push_back(s.camera.floatParams());
          cv::Mat im = img_full[k].clone();
          im.setTo(-1.0f, mask_full[k] != 0);
          level.images.push_back(im);
        }
        level.poses.push_back(toViewPose(T_view_ref));
      }
      backend_->sweep(level, planes, config_, range, cost, ratio);
      return cam;
    };
    cv::Mat range, cost, ratio, texture;
    if (config_.resolution == SweepResolution::Full) {
      run(0, &result.raw_depth, &result.cost, &result.uniqueness, &result.texture);
    } else {
      run(1, &range, &cost, &ratio, &texture);
      result.raw_depth = upsampleNearest(range, W, H);
      result.cost = upsampleNearest(cost, W, H);
      result.uniqueness = upsampleNearest(ratio, W, H);
      result.texture = upsampleNearest(texture, W, H);
      if (config_.resolution == SweepResolution::Multiscale) {
        const CameraModel crop = run(2, &range, &cost, &ratio, &texture);
        const int x0 = static_cast<int>(std::lround(ref.camera.params().cx - crop.params().cx));
        const int y0 = static_cast<int>(std::lround(ref.camera.params().cy - crop.params().cy));
        for (int v = 0; v < range.rows; ++v) {
          for (int u = 0; u < range.cols; ++u) {
            const float d = range.at<float>(v, u);
            if (!std::isfinite(d)) continue;  // the crop wins where it is valid
            result.raw_depth.at<float>(y0 + v, x0 + u) = d;
            result.cost.at<float>(y0 + v, x0 + u) = cost.at<float>(v, u);
            result.uniqueness.at<float>(y0 + v, x0 + u) = ratio.at<float>(v, u);
            result.texture.at<float>(y0 + v, x0 + u) = texture.at<float>(v, u);
          }
        }
      }
    }
    // Textureless regions (sky, blank walls): a window that reaches across
    // their edge matches the edge, so the whole region goes, grown by 2 px.
    unsigned full_version = 0;
    raysFor(0, ref.camera, ref_mask, &full_version);
    const cv::Mat region = texturelessRegions(ref_full, rays_[0].valid, config_.filters.min_texture_snr,
                                              config_.filters.min_noise_std, config_.window_full);
    result.texture.setTo(0.0f, region);
    // The depth range is a range along the ray, like the output.
    const float near = static_cast<float>(config_.near), far = static_cast<float>(config_.far);
    for (int v = 0; v < H; ++v) {
      float* d = result.raw_depth.ptr<float>(v);
      for (int u = 0; u < W; ++u) {
        if (!(d[u] >= near && d[u] <= far)) d[u] = NAN;
      }
    }
  } else {
    result.texture = cv::Mat(H, W, CV_32FC1, cv::Scalar(NAN));
  }
  result.sweep_ms = msSince(t0);
  const auto t1 = std::chrono::steady_clock::now();
  result.depth = applyDepthFilters(config_.filters, result.raw_depth, result.cost, result.uniqueness, result.texture);
  // Masked reference pixels never carry a depth (half resolution could leak).
  result.depth.setTo(NAN, ref_mask != 0);
  result.raw_depth.setTo(NAN, ref_mask != 0);
  result.filter_ms = msSince(t1);
  result.total_ms = msSince(t0);
  return result;
}

DepthFilterConfig DepthFilterConfig::fromParams(const ParamSource& p, DepthFilterConfig base) {
  DepthFilterConfig& f = base;
  p.get("filter_texture", f.texture);
  p.get("min_texture_snr", f.min_texture_snr);
  p.get("min_noise_std", f.min_noise_std);
  p.get("filter_cost", f.cost);
  p.get("alpha_upper", f.alpha_upper);
  p.get("alpha_lower", f.alpha_lower);
  p.get("split_row", f.split_row);
  p.get("filter_uniqueness", f.uniqueness);
  p.get("max_ratio", f.max_ratio);
  p.get("filter_consistency", f.consistency);
  p.get("consistency_window", f.consistency_window);
  p.get("gamma", f.gamma);
  p.get("delta", f.delta);
  f.validate();
  return f;
}

PlaneSweepConfig PlaneSweepConfig::fromParams(const ParamSource& p) { return fromParams(p, PlaneSweepConfig()); }

PlaneSweepConfig PlaneSweepConfig::fromParams(const ParamSource& p, PlaneSweepConfig base) {
  PlaneSweepConfig& c = base;
  p.get("fronto_planes", c.fronto_planes);
  p.get("near", c.near);
  p.get("far", c.far);
  p.get("ground_planes", c.ground_planes);
  p.get("ground_height", c.ground_height);
  p.get("ground_min", c.ground_min);
  p.get("ground_max", c.ground_max);
  p.get("window_full", c.window_full);
  p.get("window_half", c.window_half);
  if (std::string v; p.get("aggregation", v)) c.aggregation = parseSweepAggregation(v);
  p.get("best_k", c.best_k);
  p.get("subpixel", c.subpixel);
  if (std::string v; p.get("resolution", v)) c.resolution = parseSweepResolution(v);
  p.get("crop_width", c.crop_width);
  p.get("crop_height", c.crop_height);
  p.get("min_parallax_px", c.min_parallax_px);
  p.get("min_parallax_ratio", c.min_parallax_ratio);
  p.get("min_overlap", c.min_overlap);
  if (std::string v; p.get("backend", v)) c.backend = parseSweepBackend(v);
  p.get("device", c.device);
  c.filters = DepthFilterConfig::fromParams(p, c.filters);
  c.validate();
  return c;
}

}  // namespace fisheye_mapping
