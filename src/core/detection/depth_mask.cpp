#include "fisheye_mapping/core/detection/depth_mask.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

#include "fisheye_mapping/core/common/params.h"

namespace fisheye_mapping {

void DepthMaskConfig::validate() const {
  requireField(std::isfinite(margin_px) && margin_px >= 0, "margin_px", "must be >= 0 pixels", margin_px);
  requireField(std::isfinite(wait_for_detections) && wait_for_detections >= 0, "wait_for_detections",
          "must be >= 0 seconds", wait_for_detections);
  requireField(max_pending >= 1, "max_pending", "must be at least 1", max_pending);
  requireField(!std::isnan(time_reset_threshold), "time_reset_threshold", "must be a number of seconds (<= 0: never)",
          time_reset_threshold);
  requireField(std::isfinite(colour_near) && colour_near > 0, "colour_range", "near must be positive", colour_near);
  requireField(std::isfinite(colour_far) && colour_far > colour_near, "colour_range", "far must be greater than near",
          colour_far);
}

DepthMaskConfig DepthMaskConfig::fromParams(const ParamSource& p, DepthMaskConfig base) {
  DepthMaskConfig c = std::move(base);
  p.get("margin_px", c.margin_px);
  p.get("wait_for_detections", c.wait_for_detections);
  p.get("max_pending", c.max_pending);
  p.get("time_reset_threshold", c.time_reset_threshold);
  if (std::vector<double> range; p.get("colour_range", range)) {
    if (range.size() != 2)
      throw std::invalid_argument("colour_range: needs 2 values [near, far], got " + std::to_string(range.size()));
    c.colour_near = range[0];
    c.colour_far = range[1];
  }
  c.validate();
  return c;
}

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
