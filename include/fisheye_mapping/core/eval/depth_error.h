// Depth error statistics against ground truth (evaluation; fisheye_mapping_sim).
// Depth = CV_32FC1 range along the pixel's ray in metres, NaN invalid.
#ifndef FISHEYE_MAPPING_CORE_EVAL_DEPTH_ERROR_H_
#define FISHEYE_MAPPING_CORE_EVAL_DEPTH_ERROR_H_

#include <cstddef>

#include <opencv2/core.hpp>

namespace fisheye_mapping {

struct DepthErrorStats {
  double median = 0.0;     // of |depth - truth| over pixels valid in both
  double mean = 0.0;
  double median_far = 0.0; // the same over pixels whose true range > far_threshold
  size_t valid = 0;        // pixels valid in both
  size_t valid_far = 0;
  size_t truth_valid = 0;  // pixels with a true range
  double coverage() const { return truth_valid ? static_cast<double>(valid) / truth_valid : 0.0; }
};

// Absolute range error of `depth` against `truth` (same size). Pixels with
// a non-zero `ignore` mask value (optional) are left out, as are true ranges
// beyond max_range.
DepthErrorStats depthError(const cv::Mat& depth, const cv::Mat& truth, const cv::Mat& ignore = cv::Mat(),
                           double far_threshold = 15.0, double max_range = 1e9);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_EVAL_DEPTH_ERROR_H_
