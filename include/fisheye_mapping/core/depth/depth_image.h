// Depth images: colour coding and float TIFF output (error statistics against
// ground truth are in core/eval/depth_error.h).
// Depth = CV_32FC1 range along the pixel's ray in metres, NaN invalid.
#ifndef FISHEYE_MAPPING_CORE_DEPTH_DEPTH_IMAGE_H_
#define FISHEYE_MAPPING_CORE_DEPTH_DEPTH_IMAGE_H_

#include <string>

#include <opencv2/core.hpp>

#include "fisheye_mapping/core/camera/camera_model.h"

namespace fisheye_mapping {

// BGR image colour-coding inverse depth between near (red end) and far (blue
// end) with OpenCV's JET map; invalid pixels black.
cv::Mat colorizeDepth(const cv::Mat& depth, double near, double far);

// Writes depth as a 32-bit float TIFF (NaN kept) through writeFileSafely
// (core/common/safe_write.h); throws std::runtime_error naming the path (and
// the OS error) when it cannot.
void writeDepthTiff(const std::string& path, const cv::Mat& depth);
// Writes an image in the format its extension names (cv::imencode: .png,
// .jpg, .tiff, ...) through writeFileSafely; throws std::runtime_error naming
// the path (and the OS error) when it cannot.
void writeImageFile(const std::string& path, const cv::Mat& image);

// Range -> z-depth (REP 118: metres along the optical axis, as pinhole
// consumers such as depth_image_proc expect): z = range * ray.z with the
// pixel's unit ray. NaN stays NaN; pixels without a valid ray (outside a
// fisheye's image circle) or whose ray does not point in front of the camera
// (ray.z <= 0, past 90 deg off the axis) become NaN, as z-depth cannot hold
// them. Built once per camera (unprojection inverts the distortion by Newton
// steps), then one multiplication per pixel and frame. Thread-safe after
// construction.
class ZDepthConverter {
 public:
  explicit ZDepthConverter(const CameraModel& camera);
  // z-depth of a range image of the camera's size (CV_32FC1); throws
  // std::invalid_argument naming the type or size otherwise.
  cv::Mat convert(const cv::Mat& range) const;
  // The z component of each pixel's unit ray (CV_32FC1, NaN where none).
  const cv::Mat& rayZ() const { return ray_z_; }

 private:
  cv::Mat ray_z_;
};

// One-off conversion (builds a ZDepthConverter: per frame, keep one instead).
cv::Mat rangeToZDepth(const cv::Mat& range, const CameraModel& camera);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_DEPTH_DEPTH_IMAGE_H_
