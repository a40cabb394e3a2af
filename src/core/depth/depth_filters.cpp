// The depth filters of the plane sweep (Cui et al. 2019, Sec. III-A): the
// image noise estimate, textureless regions, and the cost, uniqueness,
// texture, infinity and consistency filters applied to raw depth.
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "fisheye_mapping/core/depth/plane_sweep.h"

namespace fisheye_mapping {

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
                          const cv::Mat& ratio, const cv::Mat& texture, const cv::Mat& infinity) {
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
    const float alpha = static_cast<float>(v < split ? config.alpha_upper : config.alpha_lower);
    for (int u = 0; u < w; ++u) {
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


}  // namespace fisheye_mapping
