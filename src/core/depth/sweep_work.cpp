#include "sweep_work.h"

#include <algorithm>
#include <cmath>

namespace fisheye_mapping {
namespace sweep_work {
namespace {

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

}  // namespace

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

std::vector<FmSweepPlane> quarterPlanes(const std::vector<FmSweepPlane>& planes) {
  std::vector<FmSweepPlane> quarter;
  for (size_t j = 0, index = 0; j < planes.size(); ++j) {  // index: within the family
    index = (j > 0 && planes[j - 1].family == planes[j].family) ? index + 1 : 0;
    const bool last = j + 1 == planes.size() || planes[j + 1].family != planes[j].family;
    if (index % 2 == 0 || last) quarter.push_back(planes[j]);
  }
  return quarter;
}

}  // namespace sweep_work
}  // namespace fisheye_mapping
