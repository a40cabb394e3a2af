// Native CPU plane sweep: the CPU backend of the product (the OpenCL backend
// is the GPU path; "cpu" is the slow double-precision reference).
//
// Same maths as the OpenCL kernels and the reference, through the shared
// functions of plane_sweep_shared.h / camera_model_shared.h; what differs is
// the loop structure, built for a CPU's caches and SIMD units:
//   - the reference image is cut into bands of rows, shared out to OpenMP
//     threads; each band keeps its own cost volume (planes x band pixels),
//     small enough to stay in the caches, and picks its pixels' best planes;
//   - per plane and view, each warped row is computed once (a straight-line
//     loop over contiguous floats, the camera model's dispatch folded away by
//     a template argument), then turned into horizontal window sums of W,
//     W^2, W R and the usable count; vertical sums of those give the ZNCC of
//     every pixel without running sums (no float drift along a column);
//   - a plane that meets none of a row's rays (ground planes above the
//     horizon) costs one dot product per pixel;
//   - per plane, only the tiles the level's activity marks are swept (the
//     runs of their columns in each tile row, with the window's margin), so
//     that skipped tiles cost nothing;
//   - the loops are compiled twice, for the x86-64 baseline and for
//     AVX2 + FMA (chosen at run time when the CPU has them), so one binary
//     runs everywhere and uses 8-wide vectors where it can.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstdint>
#include <cstring>
#include <utility>
#include <vector>

#include <omp.h>

#include "fisheye_mapping/core/common/cpu_features.h"
#include "fisheye_mapping/core/depth/plane_sweep.h"

namespace fisheye_mapping {

// Everything one level of the sweep needs, in the layout the loops want.
struct NativeLevel {
  int w = 0, h = 0, r = 0, views = 0, n_planes = 0;
  int mode = FM_AGGREGATE_AVERAGE, k = 1, subpixel = 1, band = 32;
  const float* rays = nullptr;  // 3 per pixel (AoS), zero = no ray
  const float* rx = nullptr;    // the same rays as three planes (SoA)
  const float* ry = nullptr;
  const float* rz = nullptr;
  const float* ref = nullptr;   // reference image and its window statistics
  const float* mean = nullptr;
  const float* stdev = nullptr;
  const FmCameraT<float>* cams = nullptr;
  const FmViewPose* poses = nullptr;
  const uint16_t* const* quads = nullptr;  // per view: 4 units per pixel (see loadQuads)
  const FmSweepPlane* planes = nullptr;
  const uint8_t* active = nullptr;  // SweepLevel::active (planes x tiles), nullptr: every plane everywhere
  int tiles_x = 0, tiles_y = 0;
  float* out_range = nullptr;  // w x h each
  float* out_cost = nullptr;
  float* out_ratio = nullptr;
};

// Quad images hold intensities in [0, 1] as round(v * kQuadScale), and
// kQuadMasked where self-masked (8-bit images are off by at most 8e-6).
constexpr float kQuadScale = 65534.0f;
constexpr uint16_t kQuadMasked = 65535;

#define FM_NATIVE_INLINE [[gnu::always_inline]] inline
namespace native_generic {
#include "plane_sweep_native_impl.h"  // NOLINT(build/include)
}  // namespace native_generic

#if defined(__x86_64__) && defined(__GNUC__)
#define FM_NATIVE_HAVE_AVX2 1
#pragma GCC push_options
#pragma GCC target("avx2,fma")
namespace native_avx2 {
#include "plane_sweep_native_impl.h"  // NOLINT(build/include)
}  // namespace native_avx2
#pragma GCC pop_options
#pragma GCC push_options
#pragma GCC target("avx512f,avx512vl,avx512dq,avx512bw,avx2,fma,prefer-vector-width=512")
namespace native_avx512 {
#include "plane_sweep_native_impl.h"  // NOLINT(build/include)
}  // namespace native_avx512
#pragma GCC pop_options
#endif

namespace {

class NativeSweepBackend : public SweepBackend {
 public:
  NativeSweepBackend()
      : avx2_(cpuSimdLevel() == SimdLevel::kAvx2), avx512_(cpuSimdLevel() == SimdLevel::kAvx512) {}

  std::string name() const override { return std::string("native cpu (") + (avx512_ ? "avx512" : avx2_ ? "avx2+fma" : "baseline") + ")"; }

  void sweep(const SweepLevel& level, const std::vector<FmSweepPlane>& planes, const PlaneSweepConfig& config,
             cv::Mat* range, cv::Mat* cost, cv::Mat* ratio) override {
    const int w = level.width, h = level.height;
    const size_t npix = static_cast<size_t>(w) * h;
    // The rays as three planes, once per ray table.
    Soa& soa = soa_[level.id];
    if (soa.version != level.rays_version || soa.x.size() != npix) {
      soa.x.resize(npix);
      soa.y.resize(npix);
      soa.z.resize(npix);
      const float* r = level.rays->data();
      for (size_t i = 0; i < npix; ++i) {
        soa.x[i] = r[3 * i];
        soa.y[i] = r[3 * i + 1];
        soa.z[i] = r[3 * i + 2];
      }
      soa.version = level.rays_version;
    }
    const cv::Mat ref = continuous(level.ref), mean = continuous(level.ref_mean), stdev = continuous(level.ref_std);
    // Each view's quad image: per pixel, the four pixels a bilinear sample
    // whose top-left pixel it is reads (steps clamped at the last column and
    // row as in fm_bilinear_setup), in 16-bit units, so that a sample is one
    // 8-byte load.
    quads_.resize(level.images.size());
    std::vector<const uint16_t*> quad_ptrs;
    for (size_t v = 0; v < level.images.size(); ++v) {
      const cv::Mat im = continuous(level.images[v]);
      const int iw = im.cols, ih = im.rows;
      std::vector<uint16_t>& q = quads_[v];
      q.resize(4 * im.total());
#pragma omp parallel for schedule(static)
      for (int y = 0; y < ih; ++y) {
        const float* row = im.ptr<float>(y);
        const float* below = im.ptr<float>(y + 1 < ih ? y + 1 : y);
        uint16_t* out = q.data() + 4 * static_cast<size_t>(y) * iw;
        auto unit = [](float f) -> uint16_t {  // round to nearest; no libm call
          return f < 0.0f ? kQuadMasked : static_cast<uint16_t>(std::min(f, 1.0f) * kQuadScale + 0.5f);
        };
        for (int x = 0; x < iw; ++x) {
          const int x1 = x + 1 < iw ? x + 1 : x;
          out[4 * x] = unit(row[x]);
          out[4 * x + 1] = unit(row[x1]);
          out[4 * x + 2] = unit(below[x]);
          out[4 * x + 3] = unit(below[x1]);
        }
      }
      quad_ptrs.push_back(q.data());
    }
    *range = cv::Mat(h, w, CV_32FC1);
    *cost = cv::Mat(h, w, CV_32FC1);
    *ratio = cv::Mat(h, w, CV_32FC1);

    NativeLevel L;
    L.w = w;
    L.h = h;
    L.r = level.radius;
    L.views = static_cast<int>(level.cameras.size());
    L.n_planes = static_cast<int>(planes.size());
    L.mode = config.aggregation == SweepAggregation::BestK ? FM_AGGREGATE_BEST_K : FM_AGGREGATE_AVERAGE;
    L.k = config.best_k;
    L.subpixel = config.subpixel ? 1 : 0;
    L.band = config.band_rows;
    L.rays = level.rays->data();
    L.rx = soa.x.data();
    L.ry = soa.y.data();
    L.rz = soa.z.data();
    L.ref = ref.ptr<float>();
    L.mean = mean.ptr<float>();
    L.stdev = stdev.ptr<float>();
    L.cams = level.cameras.data();
    L.poses = level.poses.data();
    L.quads = quad_ptrs.data();
    L.planes = planes.data();
    if (!level.active.empty()) {
      L.active = level.active.data();
      L.tiles_x = level.tiles_x;
      L.tiles_y = level.tiles_y;
    }
    L.out_range = range->ptr<float>();
    L.out_cost = cost->ptr<float>();
    L.out_ratio = ratio->ptr<float>();
#ifdef FM_NATIVE_HAVE_AVX2
    if (avx512_) {
      native_avx512::sweepLevel(L);
      return;
    }
    if (avx2_) {
      native_avx2::sweepLevel(L);
      return;
    }
#endif
    native_generic::sweepLevel(L);
  }

 private:
  struct Soa {
    std::vector<float> x, y, z;
    unsigned version = ~0u;
  };
  static cv::Mat continuous(const cv::Mat& m) { return m.isContinuous() ? m : m.clone(); }

  bool avx2_, avx512_;
  std::vector<std::vector<uint16_t>> quads_;
  Soa soa_[4];
};

}  // namespace

std::unique_ptr<SweepBackend> makeNativeSweepBackend() { return std::make_unique<NativeSweepBackend>(); }

}  // namespace fisheye_mapping
