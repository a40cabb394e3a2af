// Plane-sweep stereo on raw fisheye images (Cui et al. 2019, Sec. III-A;
// Häne et al. 2014): a reference view and any number of supporting views with
// known poses, each with its own camera model, no rectification.
//
// Plane families in the reference camera's frame: `fronto_planes` planes
// parallel to its image plane, uniform in inverse depth over [near, far] (z),
// `ground_planes` planes parallel to the ground (z = 0 in the base frame,
// from the mount), at heights [ground_min, ground_max], and `wall_planes` on
// each side: vertical planes parallel to the driving direction (the base
// frame's x-z plane) at lateral offsets [wall_min, wall_max] left and right
// of it, uniform in inverse offset, for the facades and parked cars' flanks
// that the front cameras see at grazing angles. Cost: (1 - ZNCC) / 2
// over a window (9x9 at full resolution, 7x7 at half), aggregated over the
// supporting views (mean, or mean of the best k); winner takes all with
// parabolic sub-plane refinement.
//
// Multi-scale: the half-resolution sweep over the whole view, upsampled, with a
// full-resolution sweep of a centre crop on top wherever the crop has a depth.
//
// Filters (each switchable): too little texture in the reference window for
// the image's noise (sky, blank walls), best cost above alpha (separate alpha
// for the upper and lower part of the image), best / second-best cost ratio
// above max_ratio, and local consistency (fewer than delta of the window's
// other pixels within gamma metres of the pixel's depth).
//
// Output depth: CV_32FC1, metres of Euclidean range along the pixel's ray,
// NaN where invalid; never outside [near, far] (range, like the output).
//
// Three backends share the warping, scoring and selection code
// (plane_sweep_shared.h): "opencl" (any OpenCL 1.2 device: the GPU path),
// "native" (C++ with OpenMP threads and SIMD loops, baseline x86-64 or
// AVX2 + FMA chosen at run time: the CPU path) and "cpu" (a plain C++
// reference in double precision, slow, for tests on small images). "auto"
// (the default) takes "opencl" when the machine has an OpenCL GPU, else
// "native".
#ifndef FISHEYE_MAPPING_CORE_DEPTH_PLANE_SWEEP_H_
#define FISHEYE_MAPPING_CORE_DEPTH_PLANE_SWEEP_H_

#include <memory>
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/camera_model.h"
#include "fisheye_mapping/core/common/params.h"
#include "fisheye_mapping/core/depth/plane_sweep_shared.h"
#include "fisheye_mapping/core/camera/rig.h"

namespace fisheye_mapping {

template <class Config>
class ParamTable;  // fisheye_mapping/core/common/param_table.h

// The enumerated parameters of PlaneSweepConfig, each parsed once from its
// parameter string (parseX throws std::invalid_argument naming the parameter,
// the allowed values and the bad one) and printed back by toString.
enum class SweepAggregation { Average, BestK };           // "average" | "best_k"
enum class SweepResolution { Full, Half, Multiscale };    // "full" | "half" | "multiscale"
enum class SweepBackendType { Auto, Native, OpenCl, Cpu };  // "auto" | "native" | "opencl" | "cpu"
SweepAggregation parseSweepAggregation(const std::string& s);
SweepResolution parseSweepResolution(const std::string& s);
SweepBackendType parseSweepBackend(const std::string& s);
std::string toString(SweepAggregation a);
std::string toString(SweepResolution r);
std::string toString(SweepBackendType b);

struct DepthFilterConfig {
  // Texture: drop pixels with too little texture to correlate: the matching
  // window's standard deviation is below the image's sensor noise at the
  // window's mean intensity (NoiseModel, estimated per frame from the
  // full-resolution image itself, at least min_noise_std; averaged down at
  // coarser scales) times min_texture_snr,
  // stated for a 3x3 window: a larger window needs the same significance
  // against pure noise, so a lower ratio (windowSnrThreshold), or the pixel
  // lies in a textureless region (sky,
  // blank walls: see texturelessRegions), where windows reaching across the
  // region's edge would match the edge.
  bool texture = true;
  double min_texture_snr = 1.5;
  double min_noise_std = 1.0 / 255.0;  // image values in [0, 1]: one 8-bit step
  bool cost = true;              // drop best cost > alpha
  double alpha_upper = 0.05;     // above the horizon (rows above split_row * height without a mount)
  double alpha_lower = 0.3;      // below it: the ground, slanted to the camera
  double split_row = 0.5;        // fraction of the image height
  // With the camera's mount known (PlaneSweep::compute's T_base_ref): a
  // pixel whose ray points below the base frame's horizontal plane gets
  // alpha_lower, others alpha_upper, whatever the camera's pitch (a camera
  // pitched down sees road in its upper rows, a fisheye's horizon is a
  // curve); split_row when off or without a mount. Off by default (the
  // paper's split): see docs/depth.md#alpha-by-the-horizon.
  bool alpha_by_horizon = false;
  bool uniqueness = true;        // drop best / second-best cost > max_ratio
  double max_ratio = 0.9;
  bool consistency = true;       // drop when < delta of the window is within gamma
  int consistency_window = 5;    // odd
  double gamma = 0.5;            // metres
  // On the road (a pixel whose point lies within the ground planes' heights;
  // needs the camera's mount) the tolerance grows with the range: max(gamma,
  // road_gamma_relative * range). The road seen at a grazing angle changes
  // its range by more than gamma from one pixel to the next beyond a few
  // metres (0.7 m a row at 13 m), and the sweep's error grows with the range
  // (its planes are uniform in inverse depth), so the far road failed the
  // check wherever it was right. Elsewhere gamma alone (spurious depth on a
  // smooth car body stays out). 0: the paper's fixed gamma everywhere.
  double road_gamma_relative = 0.0;
  double delta = 0.3;
  // Infinity: drop pixels whose best cost is not below the cost at infinity
  // (each supporting view warped by its rotation alone) by at least
  // infinity_margin. The sky, and any surface too far or too smooth for the
  // baseline to tell from the sky (a smooth intensity gradient matches at
  // every plane), has no parallax that supports its depth: without this the
  // winning plane of a cloudy sky is the noise's choice. Also drops the
  // sky's fattened edges (noParallaxEdges): a textured sky is no textureless
  // region, so windows reaching across a roof's edge give the sky beside it
  // the roof's depth. Off by default: it adds ~16 % to the multi-scale
  // depth time (docs/depth.md, "The sky").
  bool infinity = false;
  double infinity_margin = 0.01;  // cost units ((1 - ZNCC) / 2)
  // Throws std::invalid_argument naming the parameter (params().check).
  void validate() const;
  // The declaration of every filter parameter (docs/parameters.md).
  static const ParamTable<DepthFilterConfig>& params();
  // `base` overlaid with the parameters filter_texture, min_texture_snr,
  // min_noise_std, filter_cost, alpha_upper, alpha_lower, split_row,
  // filter_uniqueness, max_ratio, filter_consistency, consistency_window,
  // gamma and delta (the names of cfg/DepthReconfigure.cfg, which the
  // reconfigure callback passes through here too); validated.
  static DepthFilterConfig fromParams(const ParamSource& p, DepthFilterConfig base);
  static DepthFilterConfig fromParams(const ParamSource& p) { return fromParams(p, DepthFilterConfig()); }
};

struct PlaneSweepConfig {
  // Planes.
  int fronto_planes = 64;
  // Depth range, metres of range along the ray (the output's unit): output
  // outside [near, far] is dropped. The fronto-parallel planes span z-depths
  // near to far, so every one meets every ray within or beyond the range.
  // With ground planes and a mount, pixels whose ray meets the road
  // (ground_height) nearer than `near` are not swept and get no depth
  // (groundNearerThan): no plane holds what they see, and some took a wrong
  // plane's range, 2-4 times too far (a camera 0.65 m above the road).
  double near = 1.5;
  double far = 60.0;
  int ground_planes = 30;        // 0 disables the family
  // z of the road in the base frame, metres: 0 when the base frame lies on the
  // ground (base_footprint), e.g. -0.3 when base_link is the rear axle 0.3 m
  // above the road. The ground-plane family spans heights
  // ground_height + [ground_min, ground_max] of the base frame.
  double ground_height = 0.0;
  double ground_min = -0.3;      // plane heights above the ground (ground_height), metres
  double ground_max = 0.3;
  // Planes on each side parallel to the base frame's x-z plane (y_base =
  // +offset left, -offset right), offsets [wall_min, wall_max] from it,
  // metres, uniform in inverse offset; 0 disables the family. Only with a
  // mount, like the ground planes.
  int wall_planes = 0;
  double wall_min = 1.5;
  double wall_max = 20.0;
  // Matching.
  int window_full = 9;           // odd window sizes
  int window_half = 7;
  SweepAggregation aggregation = SweepAggregation::Average;  // "average" | "best_k"
  int best_k = 2;
  bool subpixel = true;
  // Scales: "full" | "half" | "multiscale".
  SweepResolution resolution = SweepResolution::Multiscale;
  double crop_width = 572.0 / 1024.0;   // centre crop, fractions of the full image
  double crop_height = 332.0 / 544.0;
  // Multiscale coarse-to-fine: in each tile of FM_SWEEP_TILE^2 pixels the
  // full-resolution crop sweeps only the planes within crop_search_planes
  // planes (of each family) of the half-resolution winners under and around
  // the tile (all planes where the half resolution has none); 0 sweeps every
  // plane there.
  int crop_search_planes = 1;
  // Half and multiscale, coarse-to-fine: a quarter-resolution sweep of every
  // other plane of each family first (window_quarter), then the
  // half-resolution sweep searches, in
  // each tile, only the planes within half_search_planes planes of the
  // quarter-resolution winners under and around it; 0: no quarter-resolution
  // sweep, the half resolution sweeps every plane.
  int half_search_planes = 1;
  int window_quarter = 5;
  // Not a parameter: skip the work whose result the filters would drop (tiles
  // with no pixel that can keep a depth: masked, outside the camera's domain,
  // or too little texture with the texture filter on; ground planes in tiles
  // none of whose rays meet them) and the coarse-to-fine search above. false
  // sweeps every plane at every pixel (tests compare the two: the filtered
  // depth is the same with crop_search_planes 0).
  bool skip_work = true;
  // Supporting views: kept when the parallax between the near and far planes
  // (median over the reference's pixels, full resolution, in pixels of the
  // coarser of the two images: a narrow camera's long focal length does not
  // count) is at least min_parallax_px pixels per fronto-parallel plane (a
  // baseline too short for the matching to resolve the planes adds noise and
  // its calibration error, not depth) and at least min_parallax_ratio of the
  // largest parallax among the views (mean aggregation weighs every view
  // alike, while a view's cost curve sharpens with the square of its
  // parallax: one with a third of the best's adds a ninth of the best's
  // discrimination but all of its own noise and bias), and at least
  // min_overlap of the reference's pixels (at the geometric mean of near and
  // far) are seen by the view.
  double min_parallax_px = 0.25;
  double min_parallax_ratio = 0.33;
  double min_overlap = 0.2;
  DepthFilterConfig filters;
  // Backend.
  SweepBackendType backend = SweepBackendType::Auto;  // "auto" | "native" | "opencl" | "cpu"
  std::string device;              // OpenCL device (see OpenClContext); "auto" with a
                                   // device set takes "opencl"
  int band_rows = 32;              // rows per work item of the cost kernel (opencl)
                                   // or per band of a thread (native)
  // Throws std::invalid_argument naming the parameter (params().check).
  void validate() const;
  // The declaration of every parameter, the filters' included
  // (docs/parameters.md). band_rows is not a parameter.
  static const ParamTable<PlaneSweepConfig>& params();
  // The defaults above overlaid with the parameters of the same names in `p`
  // (filters under the names of cfg/DepthReconfigure.cfg; the enumerations
  // as their strings, parsed here); validated. band_rows is not a parameter.
  static PlaneSweepConfig fromParams(const ParamSource& p);
  // The same over `base` instead of the defaults (a dynamic_reconfigure
  // callback: what the source does not hold stays as it runs).
  static PlaneSweepConfig fromParams(const ParamSource& p, PlaneSweepConfig base);
};

// One image to match, with its camera and pose relative to the reference.
struct SweepView {
  std::string name;              // for messages ("cam2")
  CameraModel camera;
  Eigen::Isometry3d T_ref_view = Eigen::Isometry3d::Identity();
  cv::Mat image;  // CV_8UC1, CV_8UC3 (BGR), CV_16UC1 or CV_32FC1 in [0, 1]
  cv::Mat mask;   // optional CV_8UC1 self-mask: non-zero = car body, not matched
};

struct DepthResult {
  cv::Mat depth;       // filtered range (CV_32FC1, NaN invalid), reference size
  cv::Mat raw_depth;   // the same before filtering
  cv::Mat cost;        // best cost, NaN where no plane had one
  cv::Mat uniqueness;  // best / second-best cost, NaN where none
  cv::Mat texture;     // reference window std / sensor noise std, as a 3x3 window's of the same significance (windowSnrThreshold); NaN where none
  cv::Mat infinity_cost;  // cost at infinity (filters.infinity), NaN where none or not computed
  std::vector<std::string> used_views;     // supporting views matched
  std::vector<std::string> dropped_views;  // "<name>: reason"
  std::vector<std::string> warnings;       // "<name>: ..." (e.g. non-finite pixels of float images, masked)
  // Share of the (plane, pixel) pairs of the swept scales that were swept
  // (PlaneSweepConfig::skip_work skips the rest); 1 when nothing was skipped.
  double swept_share = 1.0;
  double sweep_ms = 0.0;   // all scales, including transfers
  double filter_ms = 0.0;
  double total_ms = 0.0;
  double calibration_ms = 0.0;  // DepthStage: the online self-calibration's update in this call (0: none)
};

// The planes of a sweep. Without T_base_ref (reference camera -> base frame)
// there is no ground and only fronto-parallel planes are made.
std::vector<FmSweepPlane> makeSweepPlanes(const PlaneSweepConfig& config, const Eigen::Isometry3d* T_base_ref);

// Grey float image in [0, 1]; throws std::invalid_argument naming `what` for
// unsupported types.
cv::Mat toSweepImage(const cv::Mat& image, const std::string& what);

// The pixels whose ray (`rays`: 3 per pixel of a w x h image, zero = none)
// points below the base frame's horizontal plane (T_base_ref: the camera's
// mount): CV_8UC1, 255 there (where alpha_lower applies with
// alpha_by_horizon), 0 elsewhere and where there is no ray. Throws
// std::invalid_argument when rays has not 3 w h components.
cv::Mat belowHorizon(const std::vector<float>& rays, int w, int h, const Eigen::Isometry3d& T_base_ref);

// The camera's pixel rays as belowHorizon and groundNearerThan take them: 3
// floats per pixel, row-major, zero where the pixel has no ray.
std::vector<float> flatPixelRays(const CameraModel& camera);

// The pixels whose ray (`rays` as belowHorizon's) meets the plane z_base =
// height nearer than `near` (range along the ray): CV_8UC1, 255 there, 0
// elsewhere. With the road's height (ground_height) these pixels see the
// road, or something on it, nearer than the sweep's nearest range: a low
// camera's bottom rows (PlaneSweep::compute neither sweeps them nor gives
// them a depth). Throws std::invalid_argument as belowHorizon.
cv::Mat groundNearerThan(const std::vector<float>& rays, int w, int h, const Eigen::Isometry3d& T_base_ref,
                         double height, double near);

// Applies the enabled filters to raw range (NaN invalid) given the best cost,
// ratio, texture and infinity-cost images (texture / infinity may be empty:
// no texture / infinity filter; NaN infinity cost: no test there); returns
// the filtered range. `below` (CV_8UC1 of raw's size, may be empty):
// non-zero where alpha_lower applies (below the horizon); empty: the rows
// below split_row; another size throws std::invalid_argument.
cv::Mat applyDepthFilters(const DepthFilterConfig& config, const cv::Mat& raw, const cv::Mat& cost,
                          const cv::Mat& ratio, const cv::Mat& texture = cv::Mat(),
                          const cv::Mat& infinity = cv::Mat(), const cv::Mat& below = cv::Mat(),
                          const cv::Mat& road = cv::Mat());

// The pixels whose range (`range`, NaN invalid) puts their point on the road:
// z_base within [z_min, z_max] (`rays` as belowHorizon's): CV_8UC1, 255
// there. applyDepthFilters' `road` (road_gamma_relative). Throws
// std::invalid_argument as belowHorizon.
cv::Mat onTheRoad(const std::vector<float>& rays, const cv::Mat& range, const Eigen::Isometry3d& T_base_ref,
                  double z_min, double z_max);

// The pixels of `depth` (filtered range) that lie within band_px of a large
// region without depth of which a tenth is seen to match at infinity (a best
// `cost` that does not beat `infinity` by `margin`, where `texture` is at
// least min_texture_snr; empty texture: everywhere) -- the sky -- and whose
// intensity in `image` is closer to that region's local mean than to the
// mean of the depth beyond the band: the region's side of the edge, where
// the matching window reached across it and took the edge's depth
// (fattening). `valid`: the reference's pixels with a ray. CV_8UC1, 255 =
// drop.
cv::Mat noParallaxEdges(const cv::Mat& depth, const cv::Mat& cost, const cv::Mat& infinity, const cv::Mat& texture,
                        double min_texture_snr, const cv::Mat& image, const cv::Mat& valid, double margin, int band_px);

// Standard deviation of an image's sensor noise (image units), robust to
// texture: the lower quartile of the absolute response of Immerkaer's noise
// operator (the difference of two Laplacians, which cancels smooth
// intensity) over the pixels whose 3x3 neighbourhood is valid (non-zero in
// `valid`, CV_8UC1, or every pixel when empty), interpolated between the
// steps of a quantised image (quantileOfSteps). Returns 0 when there are no
// such pixels.
double estimateNoiseStd(const cv::Mat& image, const cv::Mat& valid = cv::Mat());

// A camera's sensor noise as a function of intensity I (image values in
// [0, 1]): variance a + b I (read noise and shot noise, the Poisson-Gaussian
// model of real sensors), std at least min_std.
struct NoiseModel {
  double a = 0.0, b = 0.0, min_std = 0.0;
  double variance(double intensity) const {
    return std::max(a + b * std::max(intensity, 0.0), min_std * min_std);
  }
  double stdAt(double intensity) const { return std::sqrt(variance(intensity)); }
  // The model of the image averaged over f x f pixels (white noise).
  NoiseModel averaged(int f) const { return {a / (f * f), b / (f * f), min_std / f}; }
};

// The noise model of an image (estimateNoiseStd's operator and quantile,
// over the valid pixels binned by their 3x3 mean intensity, a + b I fitted
// to the bins' variances weighted by their pixel counts, a, b >= 0). A
// bright sky has more noise than a dark road: one std for the whole image
// takes the sky's noise for texture.
NoiseModel estimateNoiseModel(const cv::Mat& image, const cv::Mat& valid, double min_std);

// The q-quantile (q in [0, 1]) of values that may come in steps: when
// several values tie at it, interpolated within the interval the tied value
// stands for (halfway to its neighbouring values), as the median of grouped
// data. Reorders *values.
double quantileOfSteps(std::vector<float>* values, double q);

// The window std / noise std a `window` x `window` window must reach to be
// as significant against pure noise as min_snr_3x3 is for a 3x3 window (the
// excess variance ratio in standard errors of the sample variance,
// sqrt(2 / (n - 1)) for n pixels): 1.5 at 3x3 is 1.23 at 7x7, 1.18 at 9x9.
double windowSnrThreshold(double min_snr_3x3, int window);

// Textureless regions of a grey float image (the sky, blank walls):
// connected (4-neighbour) areas of valid pixels whose 3x3 standard deviation
// is below min_snr times the noise std at its mean intensity and three
// quarters of whose `window` x `window` windows are below
// windowSnrThreshold(min_snr, window) times it (a road can be flat at 3x3 while its texture shows at the matching
// window's scale), each at least 0.2 % of the valid pixels, grown by 2
// pixels. CV_8UC1, 255 inside.
cv::Mat texturelessRegions(const cv::Mat& image, const cv::Mat& valid, double min_snr, const NoiseModel& noise,
                           int window);

// Which supporting views are worth matching (see PlaneSweepConfig). Returns
// their indices; *reasons gets "<name>: why" for the dropped ones.
std::vector<int> selectSupportViews(const PlaneSweepConfig& config, const CameraModel& ref,
                                    const std::vector<SweepView>& views, std::vector<std::string>* reasons);

// The scales of a sweep (SweepLevel::id; the slots of per-scale caches).
enum SweepSlot : int { kSlotFull = 0, kSlotHalf = 1, kSlotCrop = 2, kSlotQuarter = 3, kSweepSlots = 4 };

namespace sweep_work {
struct CoarsePrior;
}

// What a backend gets for one scale.
struct SweepLevel {
  int id = 0;                       // SweepSlot
  unsigned rays_version = 0;        // changes whenever `rays` changes
  const std::vector<float>* rays = nullptr;  // 3 per pixel; zero = masked / invalid
  int width = 0, height = 0;
  cv::Mat ref, ref_mean, ref_std;   // CV_32FC1: image and window statistics
  int radius = 4;
  std::vector<FmCameraT<float>> cameras;  // supporting views
  std::vector<FmViewPose> poses;          // T_view_ref
  std::vector<cv::Mat> images;            // CV_32FC1, -1 where self-masked
  // Which planes are swept where: active[(p * tiles_y + ty) * tiles_x + tx]
  // non-zero sweeps plane p over the tile of FM_SWEEP_TILE^2 pixels at
  // (tx, ty); a pixel of a tile where p is not swept has p's cost
  // FM_COST_INVALID (every backend alike). Empty: every plane everywhere.
  std::vector<uint8_t> active;
  int tiles_x = 0, tiles_y = 0;
};

class SweepBackend {
 public:
  virtual ~SweepBackend() = default;
  virtual std::string name() const = 0;
  // Range (NaN invalid), best cost and ratio at the level's resolution.
  virtual void sweep(const SweepLevel& level, const std::vector<FmSweepPlane>& planes,
                     const PlaneSweepConfig& config, cv::Mat* range, cv::Mat* cost, cv::Mat* ratio) = 0;
};
std::unique_ptr<SweepBackend> makeCpuSweepBackend();

// The matching cost of each pixel of a level at infinity: every supporting
// view warped by its rotation alone (the sweep's warp at inverse range -> 0),
// with the sweep's sampling, window, cost and aggregation functions
// (complete windows only); NaN where no view has a cost, and, when `range`
// (the level's swept range) is given, where it has no range. The same on
// every backend (computed on the CPU). Keeps each level's sample positions
// until its cameras, poses or rays change; not thread-safe.
class InfinityCost {
 public:
  cv::Mat compute(const SweepLevel& level, const PlaneSweepConfig& config, const cv::Mat& range = cv::Mat());

 private:
  struct Sample {  // fm_bilinear_setup's output
    int i00 = 0, dx = 0, dy = 0, inside = 0;
    float ax = 0.0f, ay = 0.0f;
  };
  struct Key {
    int width = 0, height = 0;
    unsigned rays_version = 0;
    std::vector<FmCameraT<float>> cameras;
    std::vector<FmViewPose> poses;
    bool operator==(const Key& o) const;
  };
  struct Cache {
    Key key;
    std::vector<std::vector<Sample>> samples;  // per view, per pixel
    // Scratch kept from frame to frame, per view: the warped view (W, W^2,
    // W R, 1) and its window sums.
    std::vector<cv::Mat> warped, sums;
  };
  const std::vector<Sample>& samples(const SweepLevel& level, int view);
  Cache cache_[kSweepSlots];
};
std::unique_ptr<SweepBackend> makeNativeSweepBackend();
std::unique_ptr<SweepBackend> makeOpenClSweepBackend(const std::string& device);

// Not thread-safe (one per thread); keeps the per-scale ray tables and the
// backend's buffers from frame to frame.
class PlaneSweep {
 public:
  // Throws std::invalid_argument for a bad config, OpenClError when the
  // OpenCL device is missing or the kernels do not build.
  explicit PlaneSweep(const PlaneSweepConfig& config);
  ~PlaneSweep();

  const PlaneSweepConfig& config() const { return config_; }
  std::string backendName() const;
  // Filter thresholds can change between frames (dynamic_reconfigure).
  void setFilters(const DepthFilterConfig& filters);

  // ref.T_ref_view is ignored (identity). T_base_ref (reference camera ->
  // base frame) places the ground planes; nullptr sweeps fronto-parallel
  // planes only. Throws std::invalid_argument naming the view for images that
  // do not match their camera, masks of the wrong size or type, float images
  // with no finite pixel, or more than FM_SWEEP_MAX_VIEWS supporting views.
  // NaN / infinite pixels of float images are masked (result.warnings says
  // how many).
  DepthResult compute(const SweepView& ref, const std::vector<SweepView>& supports,
                      const Eigen::Isometry3d* T_base_ref);

 private:
  struct Frame;
  struct LevelOutput;
  LevelOutput sweepLevel(Frame& frame, int slot, const sweep_work::CoarsePrior* prior, bool with_infinity);
  void sweepScales(Frame& frame, DepthResult* result);
  const std::vector<float>& raysFor(int slot, const CameraModel& camera, const cv::Mat& mask, unsigned* version);

  PlaneSweepConfig config_;
  std::unique_ptr<SweepBackend> backend_;
  struct RayCache {
    FmCameraT<float> camera{};
    cv::Mat mask;
    std::vector<float> rays;
    cv::Mat valid;  // CV_8UC1, 255 where `rays` has a ray (not masked, in the image)
    unsigned version = 0;
  };
  RayCache rays_[kSweepSlots];
  // groundNearerThan of the reference camera, kept with what it was made of.
  struct NearGround {
    FmCameraT<float> camera{};
    Eigen::Matrix4d T_base_ref = Eigen::Matrix4d::Zero();
    double height = NAN, near = NAN;
    cv::Mat mask;
    bool any = false;  // mask has a pixel
  };
  const cv::Mat& nearGround(const CameraModel& camera, const Eigen::Isometry3d& T_base_ref);
  NearGround near_ground_;
  InfinityCost infinity_;
};

// The rig's cameras as sweep views relative to camera `ref_index`.
SweepView rigSweepView(const Rig& rig, int index, int ref_index, const cv::Mat& image,
                       const cv::Mat& mask = cv::Mat());

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_DEPTH_PLANE_SWEEP_H_
