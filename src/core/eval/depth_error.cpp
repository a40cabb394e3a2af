#include "fisheye_mapping/core/eval/depth_error.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace fisheye_mapping {
namespace {

double median(std::vector<float>* v) {
  if (v->empty()) return NAN;
  const size_t mid = v->size() / 2;
  std::nth_element(v->begin(), v->begin() + mid, v->end());
  return (*v)[mid];
}

}  // namespace

DepthErrorStats depthError(const cv::Mat& depth, const cv::Mat& truth, const cv::Mat& ignore, double far_threshold,
                           double max_range) {
  CV_Assert(depth.type() == CV_32FC1 && truth.type() == CV_32FC1 && depth.size() == truth.size());
  std::vector<float> err, err_far;
  DepthErrorStats s;
  double sum = 0.0;
  for (int v = 0; v < depth.rows; ++v) {
    for (int u = 0; u < depth.cols; ++u) {
      const float t = truth.at<float>(v, u);
      if (!std::isfinite(t) || t > max_range || (!ignore.empty() && ignore.at<uchar>(v, u))) continue;
      ++s.truth_valid;
      const float d = depth.at<float>(v, u);
      if (!std::isfinite(d)) continue;
      const float e = std::fabs(d - t);
      err.push_back(e);
      sum += e;
      if (t > far_threshold) err_far.push_back(e);
    }
  }
  s.valid = err.size();
  s.valid_far = err_far.size();
  s.mean = err.empty() ? NAN : sum / err.size();
  s.median = median(&err);
  s.median_far = median(&err_far);
  return s;
}

}  // namespace fisheye_mapping
