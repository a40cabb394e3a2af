#include "fisheye_mapping/core/depth_image.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace fisheye_mapping {
namespace {

double median(std::vector<float>* v) {
  if (v->empty()) return NAN;
  const size_t mid = v->size() / 2;
  std::nth_element(v->begin(), v->begin() + mid, v->end());
  return (*v)[mid];
}

}  // namespace

cv::Mat colorizeDepth(const cv::Mat& depth, double near, double far) {
  CV_Assert(depth.type() == CV_32FC1 && near > 0 && far > near);
  cv::Mat grey(depth.size(), CV_8UC1, cv::Scalar(0)), valid(depth.size(), CV_8UC1, cv::Scalar(0));
  const double lo = 1.0 / far, hi = 1.0 / near;
  for (int v = 0; v < depth.rows; ++v) {
    for (int u = 0; u < depth.cols; ++u) {
      const float d = depth.at<float>(v, u);
      if (!(d > 0) || !std::isfinite(d)) continue;
      const double s = std::clamp((1.0 / d - lo) / (hi - lo), 0.0, 1.0);
      grey.at<uchar>(v, u) = static_cast<uchar>(std::lround(255 * s));
      valid.at<uchar>(v, u) = 255;
    }
  }
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_JET);
  colour.setTo(cv::Scalar(0, 0, 0), valid == 0);
  return colour;
}

void writeDepthTiff(const std::string& path, const cv::Mat& depth) {
  CV_Assert(depth.type() == CV_32FC1);
  bool ok = false;
  try {
    ok = cv::imwrite(path, depth);
  } catch (const cv::Exception& e) {
    throw std::runtime_error(path + ": cannot write depth TIFF: " + e.what());
  }
  if (!ok) throw std::runtime_error(path + ": cannot write depth TIFF");
}

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
