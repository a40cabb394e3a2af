#include "fisheye_mapping/core/depth/depth_image.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace fisheye_mapping {

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

ZDepthConverter::ZDepthConverter(const CameraModel& camera)
    : ray_z_(camera.height(), camera.width(), CV_32FC1) {
  const std::vector<Eigen::Vector3f> rays = pixelRays(camera);
  float* z = ray_z_.ptr<float>();
  for (size_t i = 0; i < rays.size(); ++i) z[i] = rays[i].z() > 0.0f ? rays[i].z() : NAN;  // NaN ray: NaN
}

cv::Mat ZDepthConverter::convert(const cv::Mat& range) const {
  if (range.type() != CV_32FC1) {
    throw std::invalid_argument("z-depth: range image must be CV_32FC1, got type " + std::to_string(range.type()));
  }
  if (range.size() != ray_z_.size()) {
    throw std::invalid_argument("z-depth: range image is " + std::to_string(range.cols) + "x" +
                                std::to_string(range.rows) + " but the camera is " +
                                std::to_string(ray_z_.cols) + "x" + std::to_string(ray_z_.rows));
  }
  cv::Mat z;
  cv::multiply(range, ray_z_, z);  // IEEE: NaN in either factor gives NaN
  return z;
}

cv::Mat rangeToZDepth(const cv::Mat& range, const CameraModel& camera) {
  return ZDepthConverter(camera).convert(range);
}

}  // namespace fisheye_mapping
