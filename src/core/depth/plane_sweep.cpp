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


// 255 where a pixel of a level can keep a depth through the filters: it has
// a ray (not masked, inside the camera's domain) and, with the texture
// filter on, enough texture (`texture`: window std / noise std, NaN where no
// ray) outside the textureless regions (`region`, the level's pixels; may be
// empty).
cv::Mat livePixels(const DepthFilterConfig& f, const cv::Mat& valid, const cv::Mat& texture, const cv::Mat& region) {
  cv::Mat live = valid != 0;
  if (!f.texture) return live;
  live &= texture >= f.min_texture_snr;  // NaN compares false
  if (!region.empty()) live &= region == 0;
  return live;
}

// The half-resolution (hw x hh) pixels all of whose 2x2 full-resolution
// pixels are set (CV_8UC1, 255); a last odd column or row counts what it has.
cv::Mat allOfQuads(const cv::Mat& full, int hw, int hh) {
  cv::Mat out(hh, hw, CV_8UC1);
  for (int y = 0; y < hh; ++y) {
    const uint8_t* a = full.ptr<uint8_t>(std::min(2 * y, full.rows - 1));
    const uint8_t* b = full.ptr<uint8_t>(std::min(2 * y + 1, full.rows - 1));
    uint8_t* o = out.ptr<uint8_t>(y);
    for (int x = 0; x < hw; ++x) {
      const int u0 = std::min(2 * x, full.cols - 1), u1 = std::min(2 * x + 1, full.cols - 1);
      o[x] = (a[u0] && a[u1] && b[u0] && b[u1]) ? 255 : 0;
    }
  }
  return out;
}

// The (plane, pixel) pairs an activity sweeps (tiles at the right and
// bottom edge count the pixels they have).
double sweptPairs(const std::vector<uint8_t>& active, int w, int h, int tiles_x, int tiles_y) {
  const size_t tiles = static_cast<size_t>(tiles_x) * tiles_y;
  double pairs = 0.0;
  for (size_t i = 0; i < active.size(); ++i) {
    if (!active[i]) continue;
    const int t = static_cast<int>(i % tiles), tx = t % tiles_x, ty = t / tiles_x;
    pairs += static_cast<double>(std::min(FM_SWEEP_TILE, w - tx * FM_SWEEP_TILE)) *
             std::min(FM_SWEEP_TILE, h - ty * FM_SWEEP_TILE);
  }
  return pairs;
}

// The coarser scale's result a finer one searches around (the half
// resolution for the crop, PlaneSweepConfig::crop_search_planes; the quarter
// resolution for the half, half_search_planes): pixel (x, y) of the finer
// level lies at ((x0 + x) / 2, (y0 + y) / 2) of the coarser.
struct CoarsePrior {
  cv::Mat range;                    // CV_32FC1 range at the coarser scale, NaN where none
  const std::vector<float>* rays = nullptr;  // 3 per pixel of the coarser scale
  int x0 = 0, y0 = 0;               // the finer level's origin, pixels of twice the coarser scale
  int planes_each_side = 2;
};

// The runs of consecutive planes of one family in a plane list, with what
// placing a point among them takes: every plane of a family has the same
// normal (fronto: the optical axis, d = z-depth) and monotonic offsets d,
// spaced in d (ground) or in 1 / d (fronto, walls), by which a point's
// fractional index is interpolated between the planes either side of it.
struct PlaneFamilyRun {
  int first = 0, count = 0, family = FM_FAMILY_FRONTO;
  bool inverse = true;
  std::vector<double> keys;  // d or 1 / d of each plane, made increasing (sign)
  double sign = 1.0;
  double key(double d) const { return sign * (inverse ? 1.0 / d : d); }
  // The fractional index of offset d along the family (may lie outside
  // [0, count - 1]: extrapolated with the end planes' spacing).
  double index(double d) const {
    if (count < 2) return 0.0;
    const double k = key(d);
    double fi;
    if (k <= keys.front()) {
      fi = (k - keys[0]) / (keys[1] - keys[0]);
    } else if (k >= keys.back()) {
      fi = (count - 1) + (k - keys[count - 1]) / (keys[count - 1] - keys[count - 2]);
    } else {
      const int i = static_cast<int>(std::upper_bound(keys.begin(), keys.end(), k) - keys.begin()) - 1;
      fi = i + (k - keys[i]) / (keys[i + 1] - keys[i]);
    }
    return std::isfinite(fi) ? std::clamp(fi, -1e6, 1e6) : 0.0;
  }
};

std::vector<PlaneFamilyRun> planeFamilies(const std::vector<FmSweepPlane>& planes) {
  std::vector<PlaneFamilyRun> runs;
  for (int j = 0; j < static_cast<int>(planes.size()); ++j) {
    if (runs.empty() || planes[j].family != runs.back().family) {
      PlaneFamilyRun r;
      r.first = j;
      r.family = planes[j].family;
      r.inverse = r.family != FM_FAMILY_GROUND;
      runs.push_back(r);
    }
    ++runs.back().count;
  }
  for (auto& r : runs) {
    const double k0 = r.key(planes[r.first].d), k1 = r.key(planes[r.first + r.count - 1].d);
    r.sign = k1 < k0 ? -1.0 : 1.0;
    for (int j = r.first; j < r.first + r.count; ++j) r.keys.push_back(r.key(planes[j].d));
  }
  return runs;
}

// SweepLevel::active for a level of w x h pixels with rays `rays` (3 per
// pixel, zero where none) and the pixels that can keep a depth (`live`): a
// plane is swept in a tile when the tile has a live pixel, for ground and
// wall planes a live pixel whose ray meets the plane (every plane of such a
// family has the same normal and a positive offset, so they meet the same
// rays), and, with a prior, the plane lies within prior->planes_each_side
// planes of its family of a coarser scale's winner under the tile or beside
// it (every plane when there is none).
std::vector<uint8_t> planeActivity(const cv::Mat& live, const std::vector<float>& rays,
                                   const std::vector<FmSweepPlane>& planes, const CoarsePrior* prior, int* tiles_x,
                                   int* tiles_y) {
  const int w = live.cols, h = live.rows, T = FM_SWEEP_TILE;
  const int tx_n = (w + T - 1) / T, ty_n = (h + T - 1) / T;
  *tiles_x = tx_n;
  *tiles_y = ty_n;
  const size_t tiles = static_cast<size_t>(tx_n) * ty_n;
  const int n = static_cast<int>(planes.size());
  const std::vector<PlaneFamilyRun> families = planeFamilies(planes);
  const int n_fam = static_cast<int>(families.size());
  std::vector<uint8_t> active(tiles * n, 0);
  std::vector<uint8_t> wanted(n), hit(n_fam);
  for (int ty = 0; ty < ty_n; ++ty) {
    for (int tx = 0; tx < tx_n; ++tx) {
      bool any_live = false;
      for (int f = 0; f < n_fam; ++f) hit[f] = families[f].family == FM_FAMILY_FRONTO ? 1 : 0;
      for (int y = ty * T; y < std::min(h, (ty + 1) * T); ++y) {
        const uint8_t* l = live.ptr<uint8_t>(y);
        for (int x = tx * T; x < std::min(w, (tx + 1) * T); ++x) {
          if (!l[x]) continue;
          any_live = true;
          const float* r = &rays[3 * (static_cast<size_t>(y) * w + x)];
          for (int f = 0; f < n_fam; ++f) {
            if (!hit[f]) hit[f] = fm_plane_inverse_range(planes[families[f].first], r[0], r[1], r[2]) > 0.0f;
          }
        }
      }
      if (!any_live) continue;
      std::fill(wanted.begin(), wanted.end(), prior ? 0 : 1);
      if (prior) {
        // The coarser scale's pixels under the tile and one beside it.
        const cv::Mat& hr = prior->range;
        const int K = prior->planes_each_side;
        const int hx0 = std::max(0, (prior->x0 + tx * T) / 2 - 1);
        const int hx1 = std::min(hr.cols - 1, (prior->x0 + std::min(w, (tx + 1) * T) - 1) / 2 + 1);
        const int hy0 = std::max(0, (prior->y0 + ty * T) / 2 - 1);
        const int hy1 = std::min(hr.rows - 1, (prior->y0 + std::min(h, (ty + 1) * T) - 1) / 2 + 1);
        bool any_winner = false;
        for (int y = hy0; y <= hy1; ++y) {
          for (int x = hx0; x <= hx1; ++x) {
            const float t = hr.at<float>(y, x);
            if (!std::isfinite(t)) continue;
            any_winner = true;
            const float* r = &(*prior->rays)[3 * (static_cast<size_t>(y) * hr.cols + x)];
            const double px = t * r[0], py = t * r[1], pz = t * r[2];
            // In each family, the planes either side of the winner's point
            // (its offset n . P along the family's normal) and K more.
            for (const PlaneFamilyRun& fam : families) {
              if (fam.count < 2) continue;
              const FmSweepPlane& p0 = planes[fam.first];
              const double g = p0.nx * px + p0.ny * py + p0.nz * pz;
              if (fam.inverse && !(g > 0.0)) continue;  // behind the camera / beyond the wall's side
              const double fi = fam.index(g);
              const int lo = std::max(0, static_cast<int>(std::floor(fi)) - K);
              const int hi = std::min(fam.count - 1, static_cast<int>(std::ceil(fi)) + K);
              for (int j = lo; j <= hi; ++j) wanted[fam.first + j] = 1;
            }
          }
        }
        if (!any_winner) std::fill(wanted.begin(), wanted.end(), 1);
      }
      const size_t tile = static_cast<size_t>(ty) * tx_n + tx;
      for (int f = 0; f < n_fam; ++f) {
        const PlaneFamilyRun& fam = families[f];
        for (int j = fam.first; j < fam.first + fam.count; ++j) active[j * tiles + tile] = (wanted[j] && hit[f]) ? 1 : 0;
      }
    }
  }
  return active;
}
}  // namespace

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
  if (T_base_ref && config.wall_planes > 0) {
    // Plane y_base = +o (left) or -o (right): s e_y . (R X_ref + t) = o with
    // s = +1 / -1, i.e. n . X_ref = d with n = s R^T e_y (pointing from the
    // camera towards the wall) and d = o - s t_y. Uniform in 1 / o, nearest
    // first (as the fronto-parallel planes).
    const double inv_min = 1.0 / config.wall_min, inv_max = 1.0 / config.wall_max;
    for (const int side : {1, -1}) {
      const Eigen::Vector3d n = side * (T_base_ref->linear().transpose() * Eigen::Vector3d::UnitY());
      const double ty = T_base_ref->translation().y();
      for (int i = 0; i < config.wall_planes; ++i) {
        const double o = 1.0 / (inv_min + (inv_max - inv_min) * i / (config.wall_planes - 1));
        const double d = o - side * ty;
        if (!(d > 0.0)) continue;  // the camera is beyond this wall
        FmSweepPlane p{};
        p.nx = static_cast<float>(n.x());
        p.ny = static_cast<float>(n.y());
        p.nz = static_cast<float>(n.z());
        p.d = static_cast<float>(d);
        p.family = side > 0 ? FM_FAMILY_WALL_LEFT : FM_FAMILY_WALL_RIGHT;
        planes.push_back(p);
      }
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
    // The quarter resolution, which only guides the half, sweeps every other
    // plane of each family (and each family's last): its winners place the
    // half's search to within a plane of the half's spacing either way.
    std::vector<FmSweepPlane> quarter_planes;
    for (size_t j = 0, index = 0; j < planes.size(); ++j) {  // index: within the family
      index = (j > 0 && planes[j - 1].family == planes[j].family) ? index + 1 : 0;
      const bool last = j + 1 == planes.size() || planes[j + 1].family != planes[j].family;
      if (index % 2 == 0 || last) quarter_planes.push_back(planes[j]);
    }
    const cv::Mat ref_full = toSweepImage(ref.image, ref.name);
    std::vector<cv::Mat> img_full, mask_full;
    for (int i : used) {
      img_full.push_back(toSweepImage(supports[i].image, supports[i].name));
      mask_full.push_back(maskWithNonFinite(checkedMask(supports[i]), supports[i], &result.warnings));
    }
    // Textureless regions (sky, blank walls): a window that reaches across
    // their edge matches the edge, so the whole region goes, grown by 2 px.
    unsigned full_version = 0;
    raysFor(0, ref.camera, ref_mask, &full_version);
    const cv::Mat region = texturelessRegions(ref_full, rays_[0].valid, config_.filters.min_texture_snr,
                                              config_.filters.min_noise_std, config_.window_full);
    // The full-resolution centre crop.
    const int cw = std::min(W, static_cast<int>(std::lround(config_.crop_width * W)));
    const int ch = std::min(H, static_cast<int>(std::lround(config_.crop_height * H)));
    const cv::Rect roi(std::clamp(static_cast<int>(std::lround(ref.camera.params().cx + 0.5 - cw / 2.0)), 0, W - cw),
                       std::clamp(static_cast<int>(std::lround(ref.camera.params().cy + 0.5 - ch / 2.0)), 0, H - ch),
                       cw, ch);
    double all_pairs = 0.0, swept_pairs = 0.0;  // (plane, pixel) pairs: DepthResult::swept_share
    // One scale: slot 0 full view, 1 half view, 2 full-resolution crop.
    // *live gets the level's pixels that can keep a depth (livePixels).
    // *infinity gets the level's cost at infinity (InfinityCost) when the
    // infinity filter is on, else stays empty.
    auto run = [&](int slot, const CoarsePrior* prior, cv::Mat* range, cv::Mat* cost, cv::Mat* ratio, cv::Mat* texture,
                   cv::Mat* live, cv::Mat* infinity) {
      SweepLevel level;
      level.id = slot;
      CameraModel cam = ref.camera;
      cv::Mat ref_img = ref_full, rmask = ref_mask, level_region = region;
      const bool half = slot == 1;
      if (half) {
        const int hw = W / 2, hh = H / 2;
        cam = ref.camera.scaled(0.5, hw, hh);
        cv::resize(ref_full, ref_img, cv::Size(hw, hh), 0, 0, cv::INTER_AREA);
        cv::resize(ref_mask, rmask, cv::Size(hw, hh), 0, 0, cv::INTER_AREA);
        rmask = rmask != 0;  // any masked pixel under a half-resolution pixel masks it
        level_region = allOfQuads(region, hw, hh);  // dropped at all four of its pixels
      } else if (slot == 3) {
        const int qw = W / 4, qh = H / 4;
        cam = ref.camera.scaled(0.25, qw, qh);
        cv::resize(ref_full, ref_img, cv::Size(qw, qh), 0, 0, cv::INTER_AREA);
        cv::resize(ref_mask, rmask, cv::Size(qw, qh), 0, 0, cv::INTER_AREA);
        rmask = rmask != 0;
        level_region = allOfQuads(allOfQuads(region, W / 2, H / 2), qw, qh);
      } else if (slot == 2) {
        cam = ref.camera.cropped(roi.x, roi.y, roi.width, roi.height);
        ref_img = ref_full(roi).clone();
        rmask = ref_mask(roi).clone();
        level_region = region(roi);
      }
      level.rays = &raysFor(slot, cam, rmask, &level.rays_version);
      level.width = cam.width();
      level.height = cam.height();
      level.ref = ref_img;
      level.radius = (slot == 3 ? config_.window_quarter : half ? config_.window_half : config_.window_full) / 2;
      windowStats(ref_img, level.radius, &level.ref_mean, &level.ref_std);
      // Texture against this scale's own noise (averaging to half resolution
      // halves it), over the pixels with a ray that is not masked.
      const cv::Mat& valid = rays_[slot].valid;
      const double noise = std::max(estimateNoiseStd(ref_img, valid), config_.filters.min_noise_std);
      level.ref_std.convertTo(*texture, CV_32F, 1.0 / noise);
      texture->setTo(NAN, valid == 0);
      // The quarter resolution only guides the half: every pixel with a ray
      // outside the textureless regions (a texture too weak for its window
      // can still be enough for the half's).
      DepthFilterConfig live_filters = config_.filters;
      if (slot == 3) live_filters.min_texture_snr = 0.0;
      *live = livePixels(live_filters, valid, *texture, level_region);
      const std::vector<FmSweepPlane>& level_planes = slot == 3 ? quarter_planes : planes;
      const double pairs = static_cast<double>(level.width) * level.height * level_planes.size();
      if (slot != 3) all_pairs += pairs;  // the quarter resolution is work on top
      swept_pairs += pairs;
      if (config_.skip_work) {
        level.active =
            planeActivity(*live, *level.rays, level_planes, prior, &level.tiles_x, &level.tiles_y);
        swept_pairs -= pairs - sweptPairs(level.active, level.width, level.height, level.tiles_x, level.tiles_y);
      }
      for (size_t k = 0; k < used.size(); ++k) {
        const SweepView& s = supports[used[k]];
        const Eigen::Isometry3d T_view_ref = s.T_ref_view.inverse();
        if (half || slot == 3) {
          const int f = half ? 2 : 4;
          const int sw = s.camera.width() / f, sh = s.camera.height() / f;
          level.cameras.push_back(s.camera.scaled(1.0 / f, sw, sh).floatParams());
          cv::Mat im, mk;
          cv::resize(img_full[k], im, cv::Size(sw, sh), 0, 0, cv::INTER_AREA);
          cv::resize(mask_full[k], mk, cv::Size(sw, sh), 0, 0, cv::INTER_AREA);
          im.setTo(-1.0f, mk != 0);  // any masked pixel under a coarser pixel masks it
          level.images.push_back(im);
        } else {
          level.cameras.push_back(s.camera.floatParams());
          cv::Mat im = img_full[k].clone();
          im.setTo(-1.0f, mask_full[k] != 0);
          level.images.push_back(im);
        }
        level.poses.push_back(toViewPose(T_view_ref));
      }
      backend_->sweep(level, level_planes, config_, range, cost, ratio);
      if (infinity) *infinity = config_.filters.infinity ? infinity_.compute(level, config_, *range) : cv::Mat();
      return cam;
    };
    cv::Mat range, cost, ratio, texture, live, infinity;
    if (config_.resolution == SweepResolution::Full) {
      run(0, nullptr, &result.raw_depth, &result.cost, &result.uniqueness, &result.texture, &live,
          &result.infinity_cost);
    } else {
      CoarsePrior quarter;
      const bool use_quarter = config_.skip_work && config_.half_search_planes > 0;
      if (use_quarter) {
        run(3, nullptr, &range, &cost, &ratio, &texture, &live, nullptr);
        quarter.range = range.clone();
        quarter.rays = &rays_[3].rays;
        quarter.planes_each_side = config_.half_search_planes;
      }
      run(1, use_quarter ? &quarter : nullptr, &range, &cost, &ratio, &texture, &live, &infinity);
      result.raw_depth = upsampleNearest(range, W, H);
      if (!infinity.empty()) result.infinity_cost = upsampleNearest(infinity, W, H);
      result.cost = upsampleNearest(cost, W, H);
      result.uniqueness = upsampleNearest(ratio, W, H);
      result.texture = upsampleNearest(texture, W, H);
      if (config_.resolution == SweepResolution::Multiscale) {
        CoarsePrior prior;
        prior.range = range.clone();
        prior.rays = &rays_[1].rays;
        prior.x0 = roi.x;
        prior.y0 = roi.y;
        prior.planes_each_side = config_.crop_search_planes;
        run(2, config_.crop_search_planes > 0 ? &prior : nullptr, &range, &cost, &ratio, &texture, &live, &infinity);
        const int x0 = roi.x, y0 = roi.y;
        for (int v = 0; v < range.rows; ++v) {
          for (int u = 0; u < range.cols; ++u) {
            const float d = range.at<float>(v, u);
            if (!std::isfinite(d)) {
              // In the crop its own, finer texture decides, also where it
              // has no depth (so skipping the crop's dead tiles changes
              // nothing).
              if (config_.filters.texture && !live.at<uint8_t>(v, u)) result.texture.at<float>(y0 + v, x0 + u) = 0.0f;
              continue;  // the crop wins where it is valid
            }
            result.raw_depth.at<float>(y0 + v, x0 + u) = d;
            result.cost.at<float>(y0 + v, x0 + u) = cost.at<float>(v, u);
            result.uniqueness.at<float>(y0 + v, x0 + u) = ratio.at<float>(v, u);
            result.texture.at<float>(y0 + v, x0 + u) = texture.at<float>(v, u);
            if (!infinity.empty()) result.infinity_cost.at<float>(y0 + v, x0 + u) = infinity.at<float>(v, u);
          }
        }
      }
    }
    result.texture.setTo(0.0f, region);
    result.swept_share = all_pairs > 0.0 ? swept_pairs / all_pairs : 1.0;
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
  result.depth = applyDepthFilters(config_.filters, result.raw_depth, result.cost, result.uniqueness, result.texture,
                                   result.infinity_cost);
  if (config_.filters.infinity && !result.infinity_cost.empty()) {
    // The sky's edges: the half resolution's windows reach window_half
    // half-resolution pixels, twice as many at full resolution.
    const int band = 2 * (config_.window_half / 2) + 1;
    result.depth.setTo(NAN, noParallaxEdges(result.depth, result.cost, result.infinity_cost,
                                            config_.filters.texture ? result.texture : cv::Mat(),
                                            config_.filters.min_texture_snr,
                                            ref.image.channels() == 1 ? ref.image : toSweepImage(ref.image, ref.name),
                                            rays_[0].valid, config_.filters.infinity_margin, band));
  }
  // Masked reference pixels never carry a depth (half resolution could leak).
  result.depth.setTo(NAN, ref_mask != 0);
  result.raw_depth.setTo(NAN, ref_mask != 0);
  result.filter_ms = msSince(t1);
  result.total_ms = msSince(t0);
  return result;
}

}  // namespace fisheye_mapping
