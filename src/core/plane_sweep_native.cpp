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
//   - the loops are compiled twice, for the x86-64 baseline and for
//     AVX2 + FMA (chosen at run time when the CPU has them), so one binary
//     runs everywhere and uses 8-wide vectors where it can.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "fisheye_mapping/core/plane_sweep.h"

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
  const float* const* images = nullptr;  // -1 where self-masked
  const FmSweepPlane* planes = nullptr;
  float* out_range = nullptr;  // w x h each
  float* out_cost = nullptr;
  float* out_ratio = nullptr;
};

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
#endif

namespace {

bool cpuHasAvx2() {
#ifdef FM_NATIVE_HAVE_AVX2
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
  return false;
#endif
}

class NativeSweepBackend : public SweepBackend {
 public:
  NativeSweepBackend() : avx2_(cpuHasAvx2()) {}

  std::string name() const override { return std::string("native cpu (") + (avx2_ ? "avx2+fma" : "baseline") + ")"; }

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
    std::vector<cv::Mat> images;
    std::vector<const float*> image_ptrs;
    for (const auto& im : level.images) {
      images.push_back(continuous(im));
      image_ptrs.push_back(images.back().ptr<float>());
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
    L.mode = config.aggregation == "best_k" ? FM_AGGREGATE_BEST_K : FM_AGGREGATE_AVERAGE;
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
    L.images = image_ptrs.data();
    L.planes = planes.data();
    L.out_range = range->ptr<float>();
    L.out_cost = cost->ptr<float>();
    L.out_ratio = ratio->ptr<float>();
#ifdef FM_NATIVE_HAVE_AVX2
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

  bool avx2_;
  Soa soa_[3];
};

}  // namespace

std::unique_ptr<SweepBackend> makeNativeSweepBackend() { return std::make_unique<NativeSweepBackend>(); }

}  // namespace fisheye_mapping
