// The matching cost at infinity (the infinity filter, DepthFilterConfig):
// each supporting view warped by its rotation alone, sampled, scored and
// aggregated with the sweep's own functions (plane_sweep_shared.h).
#include <cmath>
#include <cstring>

#include <opencv2/imgproc.hpp>

#include "fisheye_mapping/core/depth/plane_sweep.h"

namespace fisheye_mapping {

namespace {
// Inverse range of the "plane at infinity": the warp projects R r + s t, and
// s = 1e-9 (a point a million kilometres away) leaves R r to float precision
// while keeping fm_warp_project_ray's s > 0.
constexpr float kInfinityInverseRange = 1e-9f;
}  // namespace

bool InfinityCost::Key::operator==(const Key& o) const {
  return width == o.width && height == o.height && rays_version == o.rays_version && cameras.size() == o.cameras.size() &&
         std::memcmp(cameras.data(), o.cameras.data(), cameras.size() * sizeof(cameras[0])) == 0 &&
         std::memcmp(poses.data(), o.poses.data(), poses.size() * sizeof(poses[0])) == 0;
}

const std::vector<InfinityCost::Sample>& InfinityCost::samples(const SweepLevel& level, int view) {
  Cache& cache = cache_[level.id & 3];
  Key key{level.width, level.height, level.rays_version, level.cameras, level.poses};
  if (!(cache.key == key)) {
    // Where each view sees each reference ray at infinity: the bilinear
    // sample's setup (fm_bilinear_setup), which depends on the geometry
    // alone, kept until the cameras, poses or rays change.
    cache.key = key;
    cache.samples.assign(level.cameras.size(), {});
    const int npix = level.width * level.height;
    const float* rays = level.rays->data();
    for (size_t v = 0; v < level.cameras.size(); ++v) {
      std::vector<Sample>& out = cache.samples[v];
      out.resize(static_cast<size_t>(npix));
      const FmCameraT<float>& cam = level.cameras[v];
#pragma omp parallel for schedule(static)
      for (int pix = 0; pix < npix; ++pix) {
        const float rx = rays[3 * pix], ry = rays[3 * pix + 1], rz = rays[3 * pix + 2];
        float u = -1.0f, w = -1.0f;
        const bool ray = rx != 0.0f || ry != 0.0f || rz != 0.0f;
        const int ok = ray && fm_warp_project_ray(&cam, &level.poses[v], rx, ry, rz, kInfinityInverseRange, &u, &w);
        Sample& s = out[static_cast<size_t>(pix)];
        s.inside = fm_bilinear_setup(cam.width, cam.height, ok ? u : -1.0f, ok ? w : -1.0f, &s.i00, &s.dx, &s.dy,
                                     &s.ax, &s.ay);
      }
    }
  }
  return cache.samples[static_cast<size_t>(view)];
}

cv::Mat InfinityCost::compute(const SweepLevel& level, const PlaneSweepConfig& config, const cv::Mat& range) {
  const int w = level.width, h = level.height;
  const int views = static_cast<int>(level.cameras.size());
  const int r = level.radius, side = 2 * r + 1;
  const int mode = config.aggregation == SweepAggregation::BestK ? FM_AGGREGATE_BEST_K : FM_AGGREGATE_AVERAGE;
  // Per view: the warped image W as (W, W^2, W R, 1), all 0 where a sample
  // is unusable, then its window sums (one unnormalised box filter, float
  // like the backends' running sums): a window counts only when all of its
  // samples are usable, as in the backends. (Not NaN for the unusable ones:
  // a running sum never loses a NaN.)
  // The views are independent: one thread each, warp and box filter
  // (cv::boxFilter runs on one thread), into buffers kept from frame to
  // frame (fresh ones cost more in page faults than the filter itself).
  Cache& scratch = cache_[level.id & 3];
  std::vector<const std::vector<Sample>*> view_samples(static_cast<size_t>(views));
  for (int v = 0; v < views; ++v) view_samples[static_cast<size_t>(v)] = &this->samples(level, v);
  scratch.warped.resize(static_cast<size_t>(views));
  scratch.sums.resize(static_cast<size_t>(views));
  std::vector<cv::Mat>& sums = scratch.sums;
#pragma omp parallel for schedule(dynamic)
  for (int v = 0; v < views; ++v) {
    const Sample* samples = view_samples[static_cast<size_t>(v)]->data();
    cv::Mat& warped = scratch.warped[static_cast<size_t>(v)];
    warped.create(h, w, CV_32FC4);
    const float* img = level.images[v].ptr<float>();
    for (int y = 0; y < h; ++y) {
      float* out = warped.ptr<float>(y);
      const float* ref = level.ref.ptr<float>(y);
      const Sample* s = samples + static_cast<size_t>(y) * w;
      for (int x = 0; x < w; ++x) {
        const int i = s[x].i00;
        float value = fm_bilinear_blend(s[x].inside, img[i], img[i + s[x].dx], img[i + s[x].dy],
                                        img[i + s[x].dy + s[x].dx], s[x].ax, s[x].ay);
        const float ok = value >= 0.0f ? 1.0f : 0.0f;
        value *= ok;
        out[4 * x] = value;
        out[4 * x + 1] = value * value;
        out[4 * x + 2] = value * ref[x];
        out[4 * x + 3] = ok;
      }
    }
    cv::boxFilter(warped, sums[v], CV_32F, cv::Size(side, side), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
  }
  const float n = static_cast<float>(side * side);
  cv::Mat cost(h, w, CV_32FC1, cv::Scalar(NAN));
#pragma omp parallel for schedule(static)
  for (int y = r; y < h - r; ++y) {
    float* out = cost.ptr<float>(y);
    const float* d = range.empty() ? nullptr : range.ptr<float>(y);
    const float* mean_r = level.ref_mean.ptr<float>(y);
    const float* std_r = level.ref_std.ptr<float>(y);
    for (int x = r; x < w - r; ++x) {
      if (d && !(d[x] == d[x])) continue;
      float costs[FM_SWEEP_MAX_VIEWS];
      for (int v = 0; v < views; ++v) {
        const float* s = sums[v].ptr<float>(y) + 4 * x;
        costs[v] = s[3] > n - 0.5f ? fm_zncc_cost(n, s[0], s[1], s[2], mean_r[x], std_r[x]) : FM_COST_INVALID;
      }
      const float c = views > 0 ? fm_aggregate(costs, views, mode, config.best_k) : FM_COST_INVALID;
      if (c < FM_COST_INVALID) out[x] = c;
    }
  }
  return cost;
}

}  // namespace fisheye_mapping
