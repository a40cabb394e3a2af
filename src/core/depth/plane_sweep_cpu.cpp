// Reference plane sweep: plain loops, window sums computed directly in double
// precision (the OpenCL kernels use running float sums), the same warping,
// cost, aggregation and selection functions as the kernels
// (plane_sweep_shared.h). Slow: for tests on small images.
#include <cmath>

#include "fisheye_mapping/core/depth/plane_sweep.h"

namespace fisheye_mapping {
namespace {

class CpuSweepBackend : public SweepBackend {
 public:
  std::string name() const override { return "cpu reference"; }

  void sweep(const SweepLevel& level, const std::vector<FmSweepPlane>& planes, const PlaneSweepConfig& config,
             cv::Mat* range, cv::Mat* cost, cv::Mat* ratio) override {
    const int w = level.width, h = level.height, npix = w * h;
    const int views = static_cast<int>(level.cameras.size());
    const int r = level.radius;
    const int n_planes = static_cast<int>(planes.size());
    const float* rays = level.rays->data();
    const int mode = config.aggregation == SweepAggregation::BestK ? FM_AGGREGATE_BEST_K : FM_AGGREGATE_AVERAGE;
    std::vector<float> volume(static_cast<size_t>(n_planes) * npix);
    std::vector<float> warped(static_cast<size_t>(views) * npix);
    for (int p = 0; p < n_planes; ++p) {
#pragma omp parallel for schedule(static)
      for (int pix = 0; pix < npix; ++pix) {
        const float rx = rays[3 * pix], ry = rays[3 * pix + 1], rz = rays[3 * pix + 2];
        const float inv_t = fm_plane_inverse_range(planes[p], rx, ry, rz);
        for (int v = 0; v < views; ++v) {
          warped[static_cast<size_t>(v) * npix + pix] =
              fm_warp_sample_ray(&level.cameras[v], &level.poses[v], level.images[v].ptr<float>(), rx, ry, rz, inv_t);
        }
      }
#pragma omp parallel for schedule(static)
      for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
          float costs[FM_SWEEP_MAX_VIEWS];
          for (int v = 0; v < views; ++v) {
            costs[v] = FM_COST_INVALID;
            if (x < r || y < r || x >= w - r || y >= h - r) continue;
            double sw = 0, sww = 0, swr = 0;
            bool complete = true;
            for (int yy = y - r; yy <= y + r && complete; ++yy) {
              for (int xx = x - r; xx <= x + r; ++xx) {
                const double wv = warped[static_cast<size_t>(v) * npix + yy * w + xx];
                if (wv < 0.0) {
                  complete = false;
                  break;
                }
                const double rv = level.ref.at<float>(yy, xx);
                sw += wv;
                sww += wv * wv;
                swr += wv * rv;
              }
            }
            if (complete) {
              costs[v] = fm_zncc_cost(static_cast<float>((2 * r + 1) * (2 * r + 1)), static_cast<float>(sw),
                                      static_cast<float>(sww), static_cast<float>(swr),
                                      level.ref_mean.at<float>(y, x), level.ref_std.at<float>(y, x));
            }
          }
          const bool on = level.active.empty() ||
                          level.active[(static_cast<size_t>(p) * level.tiles_y + y / FM_SWEEP_TILE) * level.tiles_x +
                                       x / FM_SWEEP_TILE] != 0;
          volume[static_cast<size_t>(p) * npix + y * w + x] =
              on ? fm_aggregate(costs, views, mode, config.best_k) : FM_COST_INVALID;
        }
      }
    }
    *range = cv::Mat(h, w, CV_32FC1);
    *cost = cv::Mat(h, w, CV_32FC1);
    *ratio = cv::Mat(h, w, CV_32FC1);
#pragma omp parallel for schedule(static)
    for (int pix = 0; pix < npix; ++pix) {
      float t, c, q;
      if (!fm_select_plane(volume.data() + pix, npix, planes.data(), n_planes, rays[3 * pix], rays[3 * pix + 1],
                           rays[3 * pix + 2], config.subpixel ? 1 : 0, &t, &c, &q)) {
        t = c = q = NAN;
      }
      range->ptr<float>()[pix] = t;
      cost->ptr<float>()[pix] = c;
      ratio->ptr<float>()[pix] = q;
    }
  }
};

}  // namespace

std::unique_ptr<SweepBackend> makeCpuSweepBackend() { return std::make_unique<CpuSweepBackend>(); }

}  // namespace fisheye_mapping
