// The depth filters of the plane sweep (Cui et al. 2019, Sec. III-A): the
// image noise estimate, textureless regions, and the cost, uniqueness,
// texture, infinity and consistency filters applied to raw depth.
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "fisheye_mapping/core/depth/plane_sweep.h"

namespace fisheye_mapping {

namespace {

// A flat ray array (flatPixelRays) must hold 3 floats per pixel of a w x h image.
void checkRays(const char* who, const std::vector<float>& rays, int w, int h) {
  if (rays.size() != 3 * static_cast<size_t>(w) * h)
    throw std::invalid_argument(std::string(who) + ": " + std::to_string(rays.size()) + " ray components for a " +
                                std::to_string(w) + "x" + std::to_string(h) + " image");
}

// An optional mask of applyDepthFilters (empty, or CV_8UC1 of the depth's size).
void checkMask(const char* what, const cv::Mat& mask, const cv::Mat& raw) {
  if (!mask.empty() && (mask.size() != raw.size() || mask.type() != CV_8UC1))
    throw std::invalid_argument(std::string("applyDepthFilters: the ") + what + " mask is " +
                                std::to_string(mask.cols) + "x" + std::to_string(mask.rows) + ", the depth " +
                                std::to_string(raw.cols) + "x" + std::to_string(raw.rows) +
                                " (CV_8UC1 of the same size needed)");
}

// Immerkaer's (1996) noise operator N = [1 -2 1; -2 4 -2; 1 -2 1] at every
// pixel whose 3x3 neighbourhood is valid: f(|N|, 3x3 mean). N has zero
// response to planar intensity; on white noise of std s its response has
// std 6 s.
template <typename F>
void forNoiseResponses(const cv::Mat& image, const cv::Mat& valid, F&& f) {
  CV_Assert(image.type() == CV_32FC1 && (valid.empty() || (valid.type() == CV_8UC1 && valid.size() == image.size())));
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
      const float mean = (a[u - 1] + a[u] + a[u + 1] + b[u - 1] + b[u] + b[u + 1] + c[u - 1] + c[u] + c[u + 1]) / 9.0f;
      f(std::fabs(n), mean);
    }
  }
}

// The lower quartile of |N| as a noise std: texture and edges add to the
// upper part of the distribution. |N(0, 1)|'s quartile is 0.3186.
double noiseStdOf(std::vector<float>* responses) { return quantileOfSteps(responses, 0.25) / (0.3186 * 6.0); }

}  // namespace

double estimateNoiseStd(const cv::Mat& image, const cv::Mat& valid) {
  std::vector<float> r;
  r.reserve(static_cast<size_t>(image.rows) * image.cols / 2);
  forNoiseResponses(image, valid, [&](float n, float) { r.push_back(n); });
  return r.empty() ? 0.0 : noiseStdOf(&r);
}

NoiseModel estimateNoiseModel(const cv::Mat& image, const cv::Mat& valid, double min_std) {
  // The responses binned by their 3x3 mean intensity; each bin with enough
  // pixels gives a variance at its intensity; a + b I is fitted to them by
  // least squares weighted by the bins' counts (a, b >= 0), as a lower
  // envelope (below).
  constexpr int kBins = 16;
  constexpr size_t kMinCount = 500;
  std::vector<std::vector<float>> bins(kBins);
  std::vector<double> sum_i(kBins, 0.0);
  forNoiseResponses(image, valid, [&](float n, float mean) {
    const int k = std::clamp(static_cast<int>(mean * kBins), 0, kBins - 1);
    bins[k].push_back(n);
    sum_i[k] += mean;
  });
  struct Bin {
    double w, i, var;
  };
  std::vector<Bin> used;
  for (int k = 0; k < kBins; ++k) {
    // The darkest and brightest bins are left out: clipping at black and
    // white cuts their noise.
    if (bins[k].size() < kMinCount || k == 0 || k == kBins - 1) continue;
    const double w = static_cast<double>(bins[k].size());
    used.push_back({w, sum_i[k] / w, std::pow(noiseStdOf(&bins[k]), 2)});
  }
  NoiseModel m;
  m.min_std = min_std;
  if (used.empty()) {
    // Too few pixels in any bin (a small image): one variance for all.
    std::vector<float> all;
    for (const auto& b : bins) all.insert(all.end(), b.begin(), b.end());
    m.a = all.empty() ? 0.0 : std::pow(noiseStdOf(&all), 2);
    return m;
  }
  // Texture only adds to a bin's estimate: a bin made mostly of textured
  // pixels (a facade, foliage) reads far above the sensor's noise. The fit is
  // a lower envelope grown from the quietest bin: the bins within 1.5 x the
  // current model's variance are fitted, and again with the model that
  // gives, until the set stays the same.
  double a = used[0].var, slope = 0;
  for (const Bin& b : used) a = std::min(a, b.var);
  std::vector<char> keep(used.size(), 0);
  for (int round = 0; round < 16; ++round) {
    bool changed = false;
    for (size_t k = 0; k < used.size(); ++k) {
      const char in = used[k].var <= 1.5 * (a + slope * used[k].i) ? 1 : 0;
      changed = changed || in != keep[k];
      keep[k] = in;
    }
    if (!changed) break;
    double sw = 0, si = 0, sv = 0, sii = 0, siv = 0;
    for (size_t k = 0; k < used.size(); ++k) {
      if (!keep[k]) continue;
      const Bin& b = used[k];
      sw += b.w, si += b.w * b.i, sv += b.w * b.var, sii += b.w * b.i * b.i, siv += b.w * b.i * b.var;
    }
    a = sv / sw, slope = 0;  // one variance: the weighted mean
    const double det = sw * sii - si * si;
    if (det > 1e-12 * sw * sw) {
      const double b = (sw * siv - si * sv) / det;
      if (b > 0) {
        slope = b, a = (sv - b * si) / sw;
        if (a < 0) a = 0, slope = siv / sii;  // through the origin
      }
    }
  }
  m.a = a, m.b = slope;
  return m;
}

double quantileOfSteps(std::vector<float>* values, double q) {
  std::vector<float>& r = *values;
  if (r.empty()) return 0.0;
  const size_t k = std::min(r.size() - 1, static_cast<size_t>(q * r.size()));
  std::nth_element(r.begin(), r.begin() + k, r.end());
  const float x = r[k];
  // Values of quantised images come in steps (an 8-bit image's operator
  // responses are whole multiples of 1/255): many values equal x. Each such
  // value stands for an interval reaching halfway to the next smaller and
  // larger values, over which the tied ones are spread evenly; the quantile
  // is interpolated there (as the median of grouped data), so it moves
  // smoothly with the noise instead of jumping a step at a time.
  // Tied: equal but for float rounding (the same step summed in another order).
  const float eps = 1e-4f * std::fabs(x) + 1e-12f;
  size_t below = 0, tied = 0;
  float prev = -INFINITY, next = INFINITY;
  for (const float v : r) {
    if (v < x - eps) ++below, prev = std::max(prev, v);
    else if (v <= x + eps) ++tied;
    else next = std::min(next, v);
  }
  if (tied <= 1 || !std::isfinite(prev) || !std::isfinite(next)) return x;
  const double lo = 0.5 * (prev + x), hi = 0.5 * (x + next);
  const double within = (q * r.size() - below) / tied;
  return lo + std::clamp(within, 0.0, 1.0) * (hi - lo);
}

double windowSnrThreshold(double min_snr_3x3, int window) {
  if (!(min_snr_3x3 > 1.0) || window <= 3) return min_snr_3x3;
  // The sample variance of n pixels of pure noise has a relative standard
  // error of sqrt(2 / (n - 1)): the excess variance ratio min_snr^2 - 1 asked
  // of a 3x3 window is that many standard errors, asked again of the larger one.
  const double n = double(window) * window;
  return std::sqrt(1.0 + (min_snr_3x3 * min_snr_3x3 - 1.0) * std::sqrt(8.0 / (n - 1.0)));
}

cv::Mat texturelessRegions(const cv::Mat& image, const cv::Mat& valid, double min_snr, const NoiseModel& noise,
                           int window) {
  CV_Assert(image.type() == CV_32FC1 && valid.type() == CV_8UC1 && valid.size() == image.size() && window >= 3);
  const double window_snr = windowSnrThreshold(min_snr, window);
  // Whether a size x size window's variance is below snr^2 times the noise
  // variance at the window's mean intensity.
  auto flatAt = [&](int size, double snr) {
    cv::Mat mean, sq;
    cv::boxFilter(image, mean, CV_32F, cv::Size(size, size), cv::Point(-1, -1), true, cv::BORDER_REPLICATE);
    cv::boxFilter(image.mul(image), sq, CV_32F, cv::Size(size, size), cv::Point(-1, -1), true, cv::BORDER_REPLICATE);
    cv::Mat flat(image.size(), CV_8UC1);
    const double s2 = snr * snr;
    for (int v = 0; v < image.rows; ++v) {
      const float* m = mean.ptr<float>(v);
      const float* q = sq.ptr<float>(v);
      uint8_t* f = flat.ptr<uint8_t>(v);
      for (int u = 0; u < image.cols; ++u) f[u] = (q[u] - m[u] * m[u]) < s2 * noise.variance(m[u]) ? 255 : 0;
    }
    return flat;
  };
  const cv::Mat flat_window = flatAt(window, window_snr);
  cv::Mat flat = flatAt(3, min_snr) & (valid != 0);
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(flat, labels, stats, centroids, 4, CV_32S);
  // A region flat at 3x3 three quarters of whose windows are flat too (sky,
  // a blank wall; a road's texture shows at the window's scale: measured on
  // synthetic drives, sky regions 0.89-0.95 of their windows flat, roads and
  // sidewalks 0.45-0.66), at least 0.2 % of the valid pixels.
  std::vector<int> flat_windows(n, 0);
  for (int v = 0; v < image.rows; ++v) {
    const int* l = labels.ptr<int>(v);
    const uint8_t* w = flat_window.ptr<uint8_t>(v);
    for (int u = 0; u < image.cols; ++u) {
      if (l[u] > 0 && w[u]) ++flat_windows[l[u]];
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

cv::Mat belowHorizon(const std::vector<float>& rays, int w, int h, const Eigen::Isometry3d& T_base_ref) {
  checkRays("belowHorizon", rays, w, h);
  // The base frame's up direction in the camera frame: R^T e_z.
  const Eigen::Vector3f up = T_base_ref.linear().row(2).transpose().cast<float>();
  cv::Mat below(h, w, CV_8UC1);
  uint8_t* b = below.ptr<uint8_t>();
  for (size_t i = 0; i < static_cast<size_t>(w) * h; ++i) {
    b[i] = up.x() * rays[3 * i] + up.y() * rays[3 * i + 1] + up.z() * rays[3 * i + 2] < 0.0f ? 255 : 0;
  }
  return below;
}

std::vector<float> flatPixelRays(const CameraModel& camera) {
  const std::vector<Eigen::Vector3f> rays = pixelRays(camera);
  std::vector<float> flat(3 * rays.size(), 0.0f);
  for (size_t i = 0; i < rays.size(); ++i)
    if (rays[i].allFinite())
      for (int a = 0; a < 3; ++a) flat[3 * i + a] = rays[i][a];
  return flat;
}

cv::Mat groundNearerThan(const std::vector<float>& rays, int w, int h, const Eigen::Isometry3d& T_base_ref,
                         double height, double near) {
  checkRays("groundNearerThan", rays, w, h);
  // Ray r meets z_base = height at range (height - t_z) / (up . r), up = R^T e_z.
  const Eigen::Vector3f up = T_base_ref.linear().row(2).transpose().cast<float>();
  const float drop = static_cast<float>(T_base_ref.translation().z() - height);  // camera above the plane
  const float near_f = static_cast<float>(near);
  cv::Mat out(h, w, CV_8UC1);
  uint8_t* o = out.ptr<uint8_t>();
  for (size_t i = 0; i < static_cast<size_t>(w) * h; ++i) {
    const float down = -(up.x() * rays[3 * i] + up.y() * rays[3 * i + 1] + up.z() * rays[3 * i + 2]);
    o[i] = drop > 0.0f && down > 0.0f && drop < near_f * down ? 255 : 0;  // drop / down < near
  }
  return out;
}

cv::Mat onTheRoad(const std::vector<float>& rays, const cv::Mat& range, const Eigen::Isometry3d& T_base_ref,
                  double z_min, double z_max) {
  const int w = range.cols, h = range.rows;
  if (range.type() != CV_32FC1) throw std::invalid_argument("onTheRoad: the range must be CV_32FC1");
  checkRays("onTheRoad", rays, w, h);
  // z_base of the point at range d along ray r: t_z + d (up . r).
  const Eigen::Vector3f up = T_base_ref.linear().row(2).transpose().cast<float>();
  const float tz = static_cast<float>(T_base_ref.translation().z());
  const float lo = static_cast<float>(z_min), hi = static_cast<float>(z_max);
  cv::Mat out(h, w, CV_8UC1, cv::Scalar(0));
  for (int v = 0; v < h; ++v) {
    const float* d = range.ptr<float>(v);
    uint8_t* o = out.ptr<uint8_t>(v);
    for (int u = 0; u < w; ++u) {
      if (!std::isfinite(d[u])) continue;
      const size_t i = static_cast<size_t>(v) * w + u;
      const float z = tz + d[u] * (up.x() * rays[3 * i] + up.y() * rays[3 * i + 1] + up.z() * rays[3 * i + 2]);
      o[u] = z >= lo && z <= hi ? 255 : 0;
    }
  }
  return out;
}

cv::Mat applyDepthFilters(const DepthFilterConfig& config, const cv::Mat& raw, const cv::Mat& cost,
                          const cv::Mat& ratio, const cv::Mat& texture, const cv::Mat& infinity,
                          const cv::Mat& below, const cv::Mat& road) {
  checkMask("below-horizon", below, raw);
  checkMask("road", road, raw);
  cv::Mat depth = raw.clone();
  const bool use_infinity = config.infinity && !infinity.empty();
  const float margin = static_cast<float>(config.infinity_margin);
  const int w = raw.cols, h = raw.rows;
  const int split = static_cast<int>(std::lround(config.split_row * h));
  const bool use_texture = config.texture && !texture.empty();
  const float min_snr = static_cast<float>(config.min_texture_snr);
  for (int v = 0; v < h; ++v) {
    float* d = depth.ptr<float>(v);
    const float* c = cost.ptr<float>(v);
    const float* q = ratio.ptr<float>(v);
    const float* t = use_texture ? texture.ptr<float>(v) : nullptr;
    const float* inf = use_infinity ? infinity.ptr<float>(v) : nullptr;
    const float row_alpha = static_cast<float>(v < split ? config.alpha_upper : config.alpha_lower);
    const uint8_t* b = below.empty() ? nullptr : below.ptr<uint8_t>(v);
    const float a_up = static_cast<float>(config.alpha_upper), a_low = static_cast<float>(config.alpha_lower);
    for (int u = 0; u < w; ++u) {
      const float alpha = b ? (b[u] ? a_low : a_up) : row_alpha;
      if (t && !(t[u] >= min_snr)) d[u] = NAN;
      if (config.cost && !(c[u] <= alpha)) d[u] = NAN;
      if (config.uniqueness && !(q[u] <= config.max_ratio)) d[u] = NAN;
      if (inf && inf[u] == inf[u] && !(inf[u] - c[u] >= margin)) d[u] = NAN;  // NaN: no test
    }
  }
  if (!config.consistency) return depth;
  const cv::Mat in = depth.clone();
  const int r = config.consistency_window / 2;
  const int others = config.consistency_window * config.consistency_window - 1;
  const float gamma = static_cast<float>(config.gamma);
  const float road_gamma_relative = static_cast<float>(config.road_gamma_relative);
#pragma omp parallel for schedule(static)
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const float d = in.at<float>(v, u);
      if (!std::isfinite(d)) continue;
      const bool on_road = !road.empty() && road.at<uint8_t>(v, u);
      const float tolerance = on_road ? std::max(gamma, road_gamma_relative * d) : gamma;
      int consistent = 0;
      for (int y = std::max(0, v - r); y <= std::min(h - 1, v + r); ++y) {
        const float* row = in.ptr<float>(y);
        for (int x = std::max(0, u - r); x <= std::min(w - 1, u + r); ++x) {
          if ((x != u || y != v) && std::fabs(row[x] - d) < tolerance) ++consistent;  // NaN compares false
        }
      }
      if (consistent < config.delta * others) depth.at<float>(v, u) = NAN;
    }
  }
  return depth;
}

cv::Mat noParallaxEdges(const cv::Mat& depth, const cv::Mat& cost, const cv::Mat& infinity, const cv::Mat& texture,
                        double min_texture_snr, const cv::Mat& image, const cv::Mat& valid, double margin, int band_px) {
  const int w = depth.cols, h = depth.rows;
  // Seen at infinity: a pixel with enough texture (the pixels every sweep
  // computes alike, however much work it skips) whose best cost does not
  // beat infinity's. Without parallax: those, and the pixels with too little
  // texture to match at all.
  const float min_snr = static_cast<float>(min_texture_snr);
  cv::Mat none(h, w, CV_8UC1, cv::Scalar(0)), at_infinity(h, w, CV_8UC1, cv::Scalar(0));
  for (int v = 0; v < h; ++v) {
    const float* d = depth.ptr<float>(v);
    const float* c = cost.ptr<float>(v);
    const float* inf = infinity.ptr<float>(v);
    const float* t = texture.empty() ? nullptr : texture.ptr<float>(v);
    const uint8_t* ok = valid.ptr<uint8_t>(v);
    uint8_t* out = none.ptr<uint8_t>(v);
    uint8_t* at = at_infinity.ptr<uint8_t>(v);
    for (int u = 0; u < w; ++u) {
      const bool textured = !t || t[u] >= min_snr;
      at[u] = ok[u] && textured && inf[u] == inf[u] && !(inf[u] - c[u] >= margin) ? 255 : 0;
      out[u] = ok[u] && !(d[u] == d[u]) && (!textured || at[u]) ? 255 : 0;
    }
  }
  // Only large regions (at least 0.2 % of the pixels with a ray) a tenth of
  // which is seen to match at infinity: the sky, not the holes the filters
  // leave in a surface nor a facade's dark, textureless windows.
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(none, labels, stats, centroids, 8, CV_32S);
  const int min_area = std::max(1, static_cast<int>(0.002 * cv::countNonZero(valid)));
  std::vector<int> matched(n, 0);
  for (int v = 0; v < h; ++v) {
    const int* l = labels.ptr<int>(v);
    const uint8_t* at = at_infinity.ptr<uint8_t>(v);
    for (int u = 0; u < w; ++u) matched[l[u]] += at[u] ? 1 : 0;
  }
  std::vector<uint8_t> large(n, 0);
  for (int i = 1; i < n; ++i) {
    const int area = stats.at<int>(i, cv::CC_STAT_AREA);
    large[i] = area >= min_area && 10 * matched[i] >= area ? 255 : 0;
  }
  if (std::find(large.begin(), large.end(), 255) == large.end()) return cv::Mat(h, w, CV_8UC1, cv::Scalar(0));
  cv::Mat region(h, w, CV_8UC1);
  for (int v = 0; v < h; ++v) {
    const int* l = labels.ptr<int>(v);
    uint8_t* out = region.ptr<uint8_t>(v);
    for (int u = 0; u < w; ++u) out[u] = large[l[u]];
  }
  // The band: pixels with a depth within band_px of such a region. Their
  // windows reach into it, so their depth may be the edge's (fattening).
  cv::Mat near_region;  // a square (separable: fast)
  cv::dilate(region, near_region, cv::Mat::ones(2 * band_px + 1, 2 * band_px + 1, CV_8UC1));
  cv::Mat has_depth = depth == depth;
  const cv::Mat band = near_region & has_depth;
  const cv::Mat inner = has_depth & ~near_region;
  // A band pixel belongs to the side whose local mean intensity it is closer
  // to: the region's (a fattened edge) or the surface's beyond the band.
  // Local sums of (I in the region, region, I beyond the band, beyond the
  // band) in one box filter.
  cv::Mat grey, parts(h, w, CV_32FC4), sums;
  image.convertTo(grey, CV_32F);
  for (int v = 0; v < h; ++v) {
    const float* g = grey.ptr<float>(v);
    const uint8_t* r = region.ptr<uint8_t>(v);
    const uint8_t* in = inner.ptr<uint8_t>(v);
    float* p = parts.ptr<float>(v);
    for (int u = 0; u < w; ++u) {
      const float a = r[u] ? 1.0f : 0.0f, b = in[u] ? 1.0f : 0.0f;
      p[4 * u] = a * g[u];
      p[4 * u + 1] = a;
      p[4 * u + 2] = b * g[u];
      p[4 * u + 3] = b;
    }
  }
  cv::boxFilter(parts, sums, CV_32F, cv::Size(4 * band_px + 1, 4 * band_px + 1), cv::Point(-1, -1), false);
  cv::Mat drop(h, w, CV_8UC1, cv::Scalar(0));
  for (int v = 0; v < h; ++v) {
    const uint8_t* b = band.ptr<uint8_t>(v);
    const float* g = grey.ptr<float>(v);
    const float* sm = sums.ptr<float>(v);
    uint8_t* out = drop.ptr<uint8_t>(v);
    for (int u = 0; u < w; ++u) {
      if (!b[u]) continue;
      const float nr = sm[4 * u + 1], ni = sm[4 * u + 3];
      if (nr < 0.5f) continue;
      if (ni < 0.5f) {
        out[u] = 255;  // nothing beyond the band to belong to
        continue;
      }
      const float mr = sm[4 * u] / nr, mi = sm[4 * u + 2] / ni;
      if (std::fabs(g[u] - mr) < std::fabs(g[u] - mi)) out[u] = 255;
    }
  }
  return drop;
}

}  // namespace fisheye_mapping
