#include "fisheye_mapping/core/depth/depth_image.h"

#include <cmath>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "fisheye_mapping/core/common/safe_write.h"

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

namespace {

// `image` encoded as `ext` (cv::imencode), saved through writeFileSafely.
void encodeAndSave(const std::string& path, const std::string& ext, const cv::Mat& image, const char* what) {
  bool ok = false;
  std::vector<uchar> bytes;
  try {
    ok = cv::imencode(ext, image, bytes);
  } catch (const cv::Exception& e) {
    throw std::runtime_error(path + ": cannot write " + what + ": " + e.what());
  }
  if (!ok) throw std::runtime_error(path + ": cannot write " + what);
  writeFileSafely(path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

}  // namespace

void writeDepthTiff(const std::string& path, const cv::Mat& depth) {
  CV_Assert(depth.type() == CV_32FC1);
  encodeAndSave(path, ".tiff", depth, "depth TIFF");
}

void writeImageFile(const std::string& path, const cv::Mat& image) {
  const std::string::size_type dot = path.find_last_of('.');
  if (dot == std::string::npos || path.find('/', dot) != std::string::npos) {
    throw std::runtime_error(path + ": cannot write an image: no extension (.png, .jpg, .tiff) to choose the format");
  }
  encodeAndSave(path, path.substr(dot), image, "image");
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
