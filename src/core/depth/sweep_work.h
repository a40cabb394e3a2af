// The sweep's work skipping, internal to the depth stage (plane_sweep.cpp):
// which pixels of a level can keep a depth, which planes are swept in which
// tile (SweepLevel::active) and how many (plane, pixel) pairs that is.
#pragma once

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "fisheye_mapping/core/depth/plane_sweep.h"

namespace fisheye_mapping {
namespace sweep_work {

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

// 255 where a pixel of a level can keep a depth through the filters: it has
// a ray (not masked, inside the camera's domain) and, with the texture
// filter on, enough texture (`texture`: window std / noise std, NaN where no
// ray) outside the textureless regions (`region`, the level's pixels; may be
// empty).
cv::Mat livePixels(const DepthFilterConfig& f, const cv::Mat& valid, const cv::Mat& texture, const cv::Mat& region);

// The half-resolution (hw x hh) pixels all of whose 2x2 full-resolution
// pixels are set (CV_8UC1, 255); a last odd column or row counts what it has.
cv::Mat allOfQuads(const cv::Mat& full, int hw, int hh);

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
                                   int* tiles_y);

// The (plane, pixel) pairs an activity sweeps (tiles at the right and
// bottom edge count the pixels they have).
double sweptPairs(const std::vector<uint8_t>& active, int w, int h, int tiles_x, int tiles_y);

// The planes the quarter resolution sweeps (it only guides the half): every
// other plane of each family, and each family's last, so its winners place
// the half's search to within a plane of the half's spacing either way.
std::vector<FmSweepPlane> quarterPlanes(const std::vector<FmSweepPlane>& planes);

}  // namespace sweep_work
}  // namespace fisheye_mapping
