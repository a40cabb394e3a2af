#include "fisheye_mapping/core/detection/depth_mask.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace fisheye_mapping {

cv::Mat maskDepthBoxes(cv::Mat& depth, const std::vector<Detection>& boxes, float margin_px, int image_w,
                       int image_h) {
  if (depth.type() != CV_32FC1) throw std::invalid_argument("maskDepthBoxes: depth must be 32FC1");
  if (image_w <= 0 || image_h <= 0) throw std::invalid_argument("maskDepthBoxes: detection image size must be positive");
  if (!(margin_px >= 0.f)) throw std::invalid_argument("maskDepthBoxes: margin must be >= 0");
  cv::Mat mask(depth.size(), CV_8UC1, cv::Scalar(0));
  const float sx = float(depth.cols) / image_w, sy = float(depth.rows) / image_h;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (const auto& b : boxes) {
    if (!std::isfinite(b.x_min) || !std::isfinite(b.y_min) || !std::isfinite(b.x_max) || !std::isfinite(b.y_max))
      continue;
    // Pixel u is inside when its centre u + 0.5 lies in [x_min - m, x_max + m] (depth pixels).
    const int u0 = std::max(0, int(std::ceil((b.x_min - margin_px) * sx - 0.5f)));
    const int u1 = std::min(depth.cols - 1, int(std::floor((b.x_max + margin_px) * sx - 0.5f)));
    const int v0 = std::max(0, int(std::ceil((b.y_min - margin_px) * sy - 0.5f)));
    const int v1 = std::min(depth.rows - 1, int(std::floor((b.y_max + margin_px) * sy - 0.5f)));
    for (int v = v0; v <= v1; ++v) {
      float* d = depth.ptr<float>(v);
      uchar* m = mask.ptr<uchar>(v);
      for (int u = u0; u <= u1; ++u) {
        d[u] = nan;
        m[u] = 255;
      }
    }
  }
  return mask;
}

}  // namespace fisheye_mapping
