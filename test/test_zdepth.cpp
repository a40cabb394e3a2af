// Range -> z-depth (REP 118): the range image of the plane z = d comes back
// as d everywhere the camera sees it; hand-computed pixels of undistorted Mei
// cameras (xi = 1 and xi = 2), rays behind the camera and outside the image
// circle, NaN kept.
#include <cmath>
#include <stdexcept>

#include <gtest/gtest.h>

#include "fisheye_mapping/core/depth/depth_image.h"
#include "test_utils.h"

namespace fisheye_mapping {
namespace {

// Range of the plane z = d along each pixel's ray (d / ray.z) where the ray
// meets it; `behind` where the ray points away from the plane (some other
// surface: z-depth must drop it); NaN where the pixel has no ray, and on the
// grazing rays between (0 < ray.z <= 1e-6, too far to be a test of anything).
cv::Mat planeRange(const CameraModel& cam, double d, float behind) {
  cv::Mat range(cam.height(), cam.width(), CV_32FC1);
  for (int v = 0; v < cam.height(); ++v) {
    for (int u = 0; u < cam.width(); ++u) {
      Eigen::Vector3d ray;
      float& r = range.at<float>(v, u);
      if (!cam.unproject(Eigen::Vector2d(u, v), &ray)) {
        r = NAN;
      } else if (ray.z() <= 0.0) {
        r = behind;
      } else if (ray.z() <= 1e-6) {
        r = NAN;
      } else {
        r = static_cast<float>(d / ray.z());
      }
    }
  }
  return range;
}

TEST(ZDepth, PlaneInFrontOfAFisheyeIsFlat) {
  const double d = 4.0;
  for (const auto& named : test::realisticCameras()) {
    SCOPED_TRACE(named.first);
    const CameraModel& cam = named.second;
    cv::Mat range = planeRange(cam, d, 7.0f);
    // The range image really is the plane: each pixel's 3D point projects
    // back onto that pixel.
    for (int v = 0; v < cam.height(); v += 37) {
      for (int u = 0; u < cam.width(); u += 41) {
        Eigen::Vector3d ray;
        if (!cam.unproject(Eigen::Vector2d(u, v), &ray) || ray.z() <= 1e-6) continue;
        Eigen::Vector2d uv;
        ASSERT_TRUE(cam.project(range.at<float>(v, u) * ray, &uv));
        EXPECT_NEAR((uv - Eigen::Vector2d(u, v)).norm(), 0.0, 1e-2) << u << "," << v;
      }
    }
    range.at<float>(cam.height() / 2, cam.width() / 2) = NAN;  // centre: certainly on the plane
    const ZDepthConverter converter(cam);
    const cv::Mat z = converter.convert(range);
    ASSERT_EQ(z.type(), CV_32FC1);
    ASSERT_EQ(z.size(), range.size());
    int on_plane = 0, dropped = 0;
    for (int v = 0; v < cam.height(); ++v) {
      for (int u = 0; u < cam.width(); ++u) {
        const float r = range.at<float>(v, u), zd = z.at<float>(v, u);
        if (std::isnan(r) || r == 7.0f) {  // no ray, NaN input, or a ray past 90 deg
          EXPECT_TRUE(std::isnan(zd)) << u << "," << v << " z " << zd;
          dropped += std::isnan(zd);
        } else {
          ASSERT_NEAR(zd, d, 1e-5) << u << "," << v << " range " << r;
          ++on_plane;
        }
      }
    }
    EXPECT_TRUE(std::isnan(z.at<float>(cam.height() / 2, cam.width() / 2)));
    EXPECT_GT(on_plane, cam.width() * cam.height() / 2);
    EXPECT_GT(dropped, 0);
    // The one-off function agrees, NaN for NaN.
    const cv::Mat z2 = rangeToZDepth(range, cam);
    int same = 0;
    for (int v = 0; v < z.rows; ++v) {
      for (int u = 0; u < z.cols; ++u) {
        const float a = z.at<float>(v, u), b = z2.at<float>(v, u);
        same += a == b || (std::isnan(a) && std::isnan(b));
      }
    }
    EXPECT_EQ(same, z.rows * z.cols);
  }
}

// Mei without distortion, f = 300, centre (319, 239), 640 x 480: the pixel u
// on the centre row has m = (u - 319) / 300 and the unit ray (eta m, 0,
// eta - xi), eta = (xi + sqrt(1 + (1 - xi^2) m^2)) / (1 + m^2).
CameraModel undistortedMei(double xi) {
  return CameraModel::unified(test::makeIntrinsics(300, 300, 319, 239, 640, 480), xi);
}

TEST(ZDepth, HandCheckedPixelsXiOne) {
  // xi = 1: ray.z = (1 - m^2) / (1 + m^2).
  const CameraModel cam = undistortedMei(1.0);
  cv::Mat range(480, 640, CV_32FC1, cv::Scalar(10.0f));
  const cv::Mat z = rangeToZDepth(range, cam);
  // u = 544: m = 0.75, z = 0.4375 / 1.5625 = 0.28 of the range.
  EXPECT_NEAR(z.at<float>(239, 544), 2.8, 1e-5);
  // u = 589, 50 px from the edge: m = 0.9, z = 0.19 / 1.81.
  EXPECT_NEAR(z.at<float>(239, 589), 10.0 * 0.19 / 1.81, 1e-5);
  // The optical axis: z = range.
  EXPECT_NEAR(z.at<float>(239, 319), 10.0, 1e-6);
  // u = 639: m = 16/15 > 1, the ray points behind the image plane (z < 0).
  EXPECT_TRUE(std::isnan(z.at<float>(239, 639)));
  // The corner: m^2 = (319^2 + 239^2) / 300^2 > 1, behind too.
  EXPECT_TRUE(std::isnan(z.at<float>(0, 0)));
}

TEST(ZDepth, HandCheckedPixelsOutsideTheImageCircle) {
  // xi = 2: rays exist only for m^2 <= 1 / (xi^2 - 1) = 1/3.
  const CameraModel cam = undistortedMei(2.0);
  cv::Mat range(480, 640, CV_32FC1, cv::Scalar(10.0f));
  const cv::Mat z = rangeToZDepth(range, cam);
  // u = 439: m = 0.4, eta = (2 + sqrt(1 - 3 * 0.16)) / 1.16, z = eta - 2.
  const double eta = (2.0 + std::sqrt(0.52)) / 1.16;
  EXPECT_NEAR(z.at<float>(239, 439), 10.0 * (eta - 2.0), 1e-5);
  EXPECT_NEAR(eta - 2.0, 0.3457846, 1e-6);  // the formula, evaluated by hand
  // u = 499: m = 0.6, m^2 = 0.36 > 1/3: outside the image circle.
  EXPECT_TRUE(std::isnan(z.at<float>(239, 499)));
  EXPECT_TRUE(std::isnan(ZDepthConverter(cam).rayZ().at<float>(239, 499)));
}

TEST(ZDepth, NanStaysNanAndBadInputIsNamed) {
  const CameraModel cam = undistortedMei(1.0);
  cv::Mat range(480, 640, CV_32FC1, cv::Scalar(5.0f));
  range.at<float>(239, 319) = NAN;
  const ZDepthConverter converter(cam);
  const cv::Mat z = converter.convert(range);
  EXPECT_TRUE(std::isnan(z.at<float>(239, 319)));
  // u = 320: m = 1/300, z = 5 (1 - m^2) / (1 + m^2).
  const double m2 = 1.0 / 90000.0;
  EXPECT_NEAR(z.at<float>(239, 320), 5.0 * (1.0 - m2) / (1.0 + m2), 1e-6);
  try {
    converter.convert(cv::Mat(240, 320, CV_32FC1, cv::Scalar(1.0f)));
    ADD_FAILURE() << "no error for a 320x240 range image";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("320x240 but the camera is 640x480"), std::string::npos) << e.what();
  }
  EXPECT_THROW(converter.convert(cv::Mat(480, 640, CV_64FC1, cv::Scalar(1.0))), std::invalid_argument);
}

}  // namespace
}  // namespace fisheye_mapping
