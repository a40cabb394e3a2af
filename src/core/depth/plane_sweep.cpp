#include "fisheye_mapping/core/depth/plane_sweep.h"

#include "fisheye_mapping/core/common/opencl_context.h"
#include "sweep_work.h"

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

const cv::Mat& PlaneSweep::nearGround(const CameraModel& camera, const Eigen::Isometry3d& T_base_ref) {
  NearGround& c = near_ground_;
  const FmCameraT<float> params = camera.floatParams();
  const double height = config_.ground_height;
  if (c.mask.empty() || std::memcmp(&params, &c.camera, sizeof(params)) != 0 || c.T_base_ref != T_base_ref.matrix() ||
      c.height != height || c.near != config_.near) {
    c.mask = groundNearerThan(flatPixelRays(camera), camera.width(), camera.height(), T_base_ref, height, config_.near);
    c.any = cv::countNonZero(c.mask) > 0;
    c.camera = params;
    c.T_base_ref = T_base_ref.matrix();
    c.height = height;
    c.near = config_.near;
  }
  return c.mask;
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

namespace {

// The reference image, mask and textureless regions of one scale (slot) of
// the full-resolution ones, and its camera.
struct LevelReference {
  CameraModel camera;
  cv::Mat image, mask, region;
};

LevelReference levelReference(int slot, const CameraModel& full_camera, const cv::Mat& image, const cv::Mat& mask,
                              const cv::Mat& region, const cv::Rect& roi) {
  const int W = full_camera.width(), H = full_camera.height();
  LevelReference l{full_camera, image, mask, region};
  if (slot == kSlotHalf || slot == kSlotQuarter) {
    const int f = slot == kSlotHalf ? 2 : 4, w = W / f, h = H / f;
    l.camera = full_camera.scaled(1.0 / f, w, h);
    cv::resize(image, l.image, cv::Size(w, h), 0, 0, cv::INTER_AREA);
    cv::resize(mask, l.mask, cv::Size(w, h), 0, 0, cv::INTER_AREA);
    l.mask = l.mask != 0;  // any masked pixel under a coarser pixel masks it
    // Dropped at all the pixels under it.
    l.region = slot == kSlotHalf ? sweep_work::allOfQuads(region, w, h)
                                 : sweep_work::allOfQuads(sweep_work::allOfQuads(region, W / 2, H / 2), w, h);
  } else if (slot == kSlotCrop) {
    l.camera = full_camera.cropped(roi.x, roi.y, roi.width, roi.height);
    l.image = image(roi).clone();
    l.mask = mask(roi).clone();
    l.region = region(roi);
  }
  return l;
}

// A supporting view at one scale: its camera, and its image with -1 where
// self-masked (any masked pixel under a coarser pixel masks it).
void addSupportView(int slot, const SweepView& view, const cv::Mat& image, const cv::Mat& mask, SweepLevel* level) {
  const Eigen::Isometry3d T_view_ref = view.T_ref_view.inverse();
  if (slot == kSlotHalf || slot == kSlotQuarter) {
    const int f = slot == kSlotHalf ? 2 : 4;
    const int sw = view.camera.width() / f, sh = view.camera.height() / f;
    level->cameras.push_back(view.camera.scaled(1.0 / f, sw, sh).floatParams());
    cv::Mat im, mk;
    cv::resize(image, im, cv::Size(sw, sh), 0, 0, cv::INTER_AREA);
    cv::resize(mask, mk, cv::Size(sw, sh), 0, 0, cv::INTER_AREA);
    im.setTo(-1.0f, mk != 0);
    level->images.push_back(im);
  } else {
    level->cameras.push_back(view.camera.floatParams());
    cv::Mat im = image.clone();
    im.setTo(-1.0f, mask != 0);
    level->images.push_back(im);
  }
  level->poses.push_back(toViewPose(T_view_ref));
}

// Range along the ray outside [near, far] is no depth.
void limitRange(const PlaneSweepConfig& config, cv::Mat* range) {
  const float near = static_cast<float>(config.near), far = static_cast<float>(config.far);
  for (int v = 0; v < range->rows; ++v) {
    float* d = range->ptr<float>(v);
    for (int u = 0; u < range->cols; ++u) {
      if (!(d[u] >= near && d[u] <= far)) d[u] = NAN;
    }
  }
}

}  // namespace

// One compute()'s inputs at full resolution.
struct PlaneSweep::Frame {
  Frame(const SweepView& r, const std::vector<SweepView>& s) : ref(r), supports(s) {}
  const SweepView& ref;
  const std::vector<SweepView>& supports;
  std::vector<int> used;                     // the supporting views swept (indices into supports)
  cv::Mat ref_image, ref_mask, region;       // float grey, mask (with non-finite pixels), textureless regions
  std::vector<cv::Mat> images, masks;        // of the used views
  cv::Rect roi;                              // the full-resolution centre crop
  NoiseModel noise;                          // the reference image's sensor noise at full resolution
  std::vector<FmSweepPlane> planes, quarter_planes;
  double all_pairs = 0.0, swept_pairs = 0.0;  // (plane, pixel) pairs: DepthResult::swept_share
};

// One scale's sweep: range (NaN none), best cost, ratio, texture (window std
// / noise std), the pixels that can keep a depth (livePixels) and, when
// asked and the infinity filter is on, the cost at infinity (else empty).
struct PlaneSweep::LevelOutput {
  cv::Mat range, cost, ratio, texture, live, infinity;
};

PlaneSweep::LevelOutput PlaneSweep::sweepLevel(Frame& frame, int slot, const sweep_work::CoarsePrior* prior,
                                               bool with_infinity) {
  const LevelReference ref =
      levelReference(slot, frame.ref.camera, frame.ref_image, frame.ref_mask, frame.region, frame.roi);
  SweepLevel level;
  level.id = slot;
  level.rays = &raysFor(slot, ref.camera, ref.mask, &level.rays_version);
  level.width = ref.camera.width();
  level.height = ref.camera.height();
  level.ref = ref.image;
  level.radius = (slot == kSlotQuarter  ? config_.window_quarter
                  : slot == kSlotHalf ? config_.window_half
                                      : config_.window_full) /
                 2;
  windowStats(ref.image, level.radius, &level.ref_mean, &level.ref_std);
  LevelOutput out;
  // Texture against this scale's noise: the full resolution's, divided by
  // the scale factor (INTER_AREA averages f x f pixels, so white noise falls
  // by f). Estimated at each scale instead, the noise would take in more of
  // the texture the coarser the image (measured: 40-70 % too high at half
  // resolution on synthetic drives, 20-50 % at full).
  const cv::Mat& valid = rays_[slot].valid;
  const NoiseModel noise = frame.noise.averaged(slot == kSlotHalf ? 2 : slot == kSlotQuarter ? 4 : 1);
  // Stated as a 3x3 window's SNR of the same significance: compared with
  // min_texture_snr, this window's threshold is windowSnrThreshold's.
  const double min_snr = config_.filters.min_texture_snr;
  const float to_3x3 =
      static_cast<float>(min_snr > 1.0 ? min_snr / windowSnrThreshold(min_snr, 2 * level.radius + 1) : 1.0);
  out.texture.create(level.ref_std.size(), CV_32FC1);
  for (int v = 0; v < out.texture.rows; ++v) {
    const float* sd = level.ref_std.ptr<float>(v);
    const float* m = level.ref_mean.ptr<float>(v);
    float* t = out.texture.ptr<float>(v);
    for (int u = 0; u < out.texture.cols; ++u) t[u] = to_3x3 * sd[u] / static_cast<float>(noise.stdAt(m[u]));
  }
  out.texture.setTo(NAN, valid == 0);
  // The quarter resolution only guides the half: every pixel with a ray
  // outside the textureless regions (a texture too weak for its window can
  // still be enough for the half's).
  DepthFilterConfig live_filters = config_.filters;
  if (slot == kSlotQuarter) live_filters.min_texture_snr = 0.0;
  out.live = sweep_work::livePixels(live_filters, valid, out.texture, ref.region);
  const std::vector<FmSweepPlane>& planes = slot == kSlotQuarter ? frame.quarter_planes : frame.planes;
  const double pairs = static_cast<double>(level.width) * level.height * planes.size();
  if (slot != kSlotQuarter) frame.all_pairs += pairs;  // the quarter resolution is work on top
  frame.swept_pairs += pairs;
  if (config_.skip_work) {
    level.active = sweep_work::planeActivity(out.live, *level.rays, planes, prior, &level.tiles_x, &level.tiles_y);
    frame.swept_pairs -=
        pairs - sweep_work::sweptPairs(level.active, level.width, level.height, level.tiles_x, level.tiles_y);
  }
  for (size_t k = 0; k < frame.used.size(); ++k)
    addSupportView(slot, frame.supports[frame.used[k]], frame.images[k], frame.masks[k], &level);
  backend_->sweep(level, planes, config_, &out.range, &out.cost, &out.ratio);
  if (with_infinity && config_.filters.infinity) out.infinity = infinity_.compute(level, config_, out.range);
  return out;
}

// The scales config_.resolution asks for, into result's full-resolution maps.
void PlaneSweep::sweepScales(Frame& frame, DepthResult* result) {
  const int W = frame.ref.camera.width(), H = frame.ref.camera.height();
  if (config_.resolution == SweepResolution::Full) {
    LevelOutput full = sweepLevel(frame, kSlotFull, nullptr, true);
    result->raw_depth = full.range;
    result->cost = full.cost;
    result->uniqueness = full.ratio;
    result->texture = full.texture;
    result->infinity_cost = full.infinity;
    return;
  }
  sweep_work::CoarsePrior quarter;
  const bool use_quarter = config_.skip_work && config_.half_search_planes > 0;
  if (use_quarter) {
    quarter.range = sweepLevel(frame, kSlotQuarter, nullptr, false).range;
    quarter.rays = &rays_[kSlotQuarter].rays;
    quarter.planes_each_side = config_.half_search_planes;
  }
  const LevelOutput half = sweepLevel(frame, kSlotHalf, use_quarter ? &quarter : nullptr, true);
  result->raw_depth = upsampleNearest(half.range, W, H);
  if (!half.infinity.empty()) result->infinity_cost = upsampleNearest(half.infinity, W, H);
  result->cost = upsampleNearest(half.cost, W, H);
  result->uniqueness = upsampleNearest(half.ratio, W, H);
  result->texture = upsampleNearest(half.texture, W, H);
  if (config_.resolution != SweepResolution::Multiscale) return;
  sweep_work::CoarsePrior prior;
  prior.range = half.range;
  prior.rays = &rays_[kSlotHalf].rays;
  prior.x0 = frame.roi.x;
  prior.y0 = frame.roi.y;
  prior.planes_each_side = config_.crop_search_planes;
  const LevelOutput crop = sweepLevel(frame, kSlotCrop, config_.crop_search_planes > 0 ? &prior : nullptr, true);
  const int x0 = frame.roi.x, y0 = frame.roi.y;
  for (int v = 0; v < crop.range.rows; ++v) {
    for (int u = 0; u < crop.range.cols; ++u) {
      const float d = crop.range.at<float>(v, u);
      if (!std::isfinite(d)) {
        // In the crop its own, finer texture decides, also where it has no
        // depth (so skipping the crop's dead tiles changes nothing).
        if (config_.filters.texture && !crop.live.at<uint8_t>(v, u)) result->texture.at<float>(y0 + v, x0 + u) = 0.0f;
        continue;  // the crop wins where it is valid
      }
      result->raw_depth.at<float>(y0 + v, x0 + u) = d;
      result->cost.at<float>(y0 + v, x0 + u) = crop.cost.at<float>(v, u);
      result->uniqueness.at<float>(y0 + v, x0 + u) = crop.ratio.at<float>(v, u);
      result->texture.at<float>(y0 + v, x0 + u) = crop.texture.at<float>(v, u);
      if (!crop.infinity.empty()) result->infinity_cost.at<float>(y0 + v, x0 + u) = crop.infinity.at<float>(v, u);
    }
  }
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
  Frame frame(ref, supports);
  frame.ref_mask = maskWithNonFinite(checkedMask(ref), ref, &result.warnings);
  if (T_base_ref && config_.ground_planes > 0) {
    // Rays that meet the road (ground_height) nearer than `near` see it, or
    // something on it, nearer than any plane: not swept, no depth (a low
    // camera's bottom rows; before, some took a wrong plane's range).
    const cv::Mat& near_road = nearGround(ref.camera, *T_base_ref);
    if (near_ground_.any) {
      frame.ref_mask = frame.ref_mask.clone();
      frame.ref_mask.setTo(255, near_road);
    }
  }
  frame.used = selectSupportViews(config_, ref.camera, supports, &result.dropped_views);
  if (frame.used.size() > FM_SWEEP_MAX_VIEWS) {
    throw std::invalid_argument("too many supporting views: " + std::to_string(frame.used.size()) + " > " +
                                std::to_string(FM_SWEEP_MAX_VIEWS));
  }
  for (int i : frame.used) result.used_views.push_back(supports[i].name);
  const int W = ref.camera.width(), H = ref.camera.height();
  result.raw_depth = cv::Mat(H, W, CV_32FC1, cv::Scalar(NAN));
  result.cost = cv::Mat(H, W, CV_32FC1, cv::Scalar(NAN));
  result.uniqueness = cv::Mat(H, W, CV_32FC1, cv::Scalar(NAN));
  if (!frame.used.empty()) {
    frame.planes = makeSweepPlanes(config_, T_base_ref);
    frame.quarter_planes = sweep_work::quarterPlanes(frame.planes);
    frame.ref_image = toSweepImage(ref.image, ref.name);
    for (int i : frame.used) {
      frame.images.push_back(toSweepImage(supports[i].image, supports[i].name));
      frame.masks.push_back(maskWithNonFinite(checkedMask(supports[i]), supports[i], &result.warnings));
    }
    // Textureless regions (sky, blank walls): a window that reaches across
    // their edge matches the edge, so the whole region goes, grown by 2 px.
    unsigned full_version = 0;
    raysFor(kSlotFull, ref.camera, frame.ref_mask, &full_version);
    frame.noise = estimateNoiseModel(frame.ref_image, rays_[kSlotFull].valid, config_.filters.min_noise_std);
    frame.region = texturelessRegions(frame.ref_image, rays_[kSlotFull].valid, config_.filters.min_texture_snr,
                                      frame.noise, config_.window_full);
    // The full-resolution centre crop.
    const int cw = std::min(W, static_cast<int>(std::lround(config_.crop_width * W)));
    const int ch = std::min(H, static_cast<int>(std::lround(config_.crop_height * H)));
    frame.roi = cv::Rect(std::clamp(static_cast<int>(std::lround(ref.camera.params().cx + 0.5 - cw / 2.0)), 0, W - cw),
                         std::clamp(static_cast<int>(std::lround(ref.camera.params().cy + 0.5 - ch / 2.0)), 0, H - ch),
                         cw, ch);
    sweepScales(frame, &result);
    result.texture.setTo(0.0f, frame.region);
    result.swept_share = frame.all_pairs > 0.0 ? frame.swept_pairs / frame.all_pairs : 1.0;
    limitRange(config_, &result.raw_depth);  // a range along the ray, like the output
  } else {
    result.texture = cv::Mat(H, W, CV_32FC1, cv::Scalar(NAN));
  }
  result.sweep_ms = msSince(t0);
  const auto t1 = std::chrono::steady_clock::now();
  // Below the horizon: the base frame's horizontal plane through the camera.
  cv::Mat below;
  if (config_.filters.alpha_by_horizon && T_base_ref && !frame.used.empty())
    below = belowHorizon(rays_[kSlotFull].rays, W, H, *T_base_ref);
  // The road, for its range-grown consistency tolerance.
  cv::Mat road;
  if (config_.filters.consistency && config_.filters.road_gamma_relative > 0.0 && T_base_ref &&
      config_.ground_planes > 0 && !frame.used.empty())
    road = onTheRoad(rays_[kSlotFull].rays, result.raw_depth, *T_base_ref, config_.ground_height + config_.ground_min,
                     config_.ground_height + config_.ground_max);
  result.depth = applyDepthFilters(config_.filters, result.raw_depth, result.cost, result.uniqueness, result.texture,
                                   result.infinity_cost, below, road);
  if (config_.filters.infinity && !result.infinity_cost.empty()) {
    // The sky's edges: a half-resolution window reaches window_half / 2
    // half-resolution pixels, 2 (window_half / 2) + 1 at full resolution, so
    // the fattened depth lies within that reach of the true edge; the region
    // without parallax begins no nearer than the same reach beyond it (its
    // windows do not see the edge): the band is twice the reach (14 px with
    // the default 7 x 7; the reach alone, 7 px, left 1.15 % of a cloudy sky's
    // pixels with a depth on the urban drive, 0.11 % with twice it).
    const int band = 2 * (2 * (config_.window_half / 2) + 1);
    result.depth.setTo(NAN, noParallaxEdges(result.depth, result.cost, result.infinity_cost,
                                            config_.filters.texture ? result.texture : cv::Mat(),
                                            config_.filters.min_texture_snr,
                                            ref.image.channels() == 1 ? ref.image : toSweepImage(ref.image, ref.name),
                                            rays_[kSlotFull].valid, config_.filters.infinity_margin, band));
  }
  // Masked reference pixels never carry a depth (half resolution could leak).
  result.depth.setTo(NAN, frame.ref_mask != 0);
  result.raw_depth.setTo(NAN, frame.ref_mask != 0);
  result.filter_ms = msSince(t1);
  result.total_ms = msSince(t0);
  return result;
}

}  // namespace fisheye_mapping
