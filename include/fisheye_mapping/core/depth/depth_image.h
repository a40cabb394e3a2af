// Depth images: colour coding and float TIFF output (error statistics against
// ground truth are in core/eval/depth_error.h).
// Depth = CV_32FC1 range along the pixel's ray in metres, NaN invalid.
#ifndef FISHEYE_MAPPING_CORE_DEPTH_DEPTH_IMAGE_H_
#define FISHEYE_MAPPING_CORE_DEPTH_DEPTH_IMAGE_H_

#include <string>

#include <opencv2/core.hpp>

namespace fisheye_mapping {

// BGR image colour-coding inverse depth between near (red end) and far (blue
// end) with OpenCV's JET map; invalid pixels black.
cv::Mat colorizeDepth(const cv::Mat& depth, double near, double far);

// Writes depth as a 32-bit float TIFF (NaN kept); throws std::runtime_error
// naming the path when it cannot.
void writeDepthTiff(const std::string& path, const cv::Mat& depth);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_DEPTH_DEPTH_IMAGE_H_
