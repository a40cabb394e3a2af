// Camera models: hand-computed projections, validity domains, and round trips
// over the whole valid field of view.
#include <cmath>

#include <functional>

#include <gtest/gtest.h>

#include "fisheye_mapping/core/camera/camera_model.h"
#include "test_utils.h"

namespace fisheye_mapping {
namespace {

using test::makeIntrinsics;

void expectProjects(const CameraModel& cam, const Eigen::Vector3d& p, double u, double v) {
  Eigen::Vector2d uv;
  ASSERT_TRUE(cam.project(p, &uv)) << p.transpose();
  EXPECT_NEAR(uv.x(), u, 1e-9) << p.transpose();
  EXPECT_NEAR(uv.y(), v, 1e-9) << p.transpose();
  // And back: the pixel's ray is the point's direction.
  Eigen::Vector3d ray;
  ASSERT_TRUE(cam.unproject(uv, &ray));
  EXPECT_NEAR((ray - p.normalized()).norm(), 0.0, 1e-9) << p.transpose();
}

void expectInvalid(const CameraModel& cam, const Eigen::Vector3d& p) {
  Eigen::Vector2d uv;
  EXPECT_FALSE(cam.project(p, &uv)) << p.transpose();
}

// ---------------------------------------------------------------------------
// Exact projections worked out by hand (comments show the arithmetic).

TEST(UnifiedModel, HandComputedNoDistortion) {
  const auto cam = CameraModel::unified(makeIntrinsics(300, 300, 512, 272), 1.0);
  // On the axis: the principal point.
  expectProjects(cam, {0, 0, 1}, 512, 272);
  // (1,2,2): d = 3, z + xi d = 5, m = (0.2, 0.4) -> (512 + 60, 272 + 120).
  expectProjects(cam, {1, 2, 2}, 572, 392);
  // (1,0,0), 90 deg off-axis: d = 1, z + xi d = 1, m = (1, 0) -> (812, 272).
  expectProjects(cam, {1, 0, 0}, 812, 272);
  // (0,-3,-4): 143 deg off-axis, still valid for xi = 1: d = 5, denom = 1,
  // m = (0, -3) -> v = 272 - 900.
  expectProjects(cam, {0, -3, -4}, 512, -628);
}

TEST(UnifiedModel, HandComputedRadtan) {
  // k1 = 0.1, p1 = 0.01. (1,2,2): m = (0.2, 0.4), r^2 = 0.2, radial = 1.02;
  // xd = 0.204 + 2 p1 x y = 0.204 + 0.0016 = 0.2056;
  // yd = 0.408 + p1 (r^2 + 2 y^2) = 0.408 + 0.01 * 0.52 = 0.4132;
  // u = 512 + 300 * 0.2056 = 573.68, v = 272 + 300 * 0.4132 = 395.96.
  const auto cam = CameraModel::unified(makeIntrinsics(300, 300, 512, 272), 1.0, 0.1, 0.0, 0.01, 0.0);
  expectProjects(cam, {1, 2, 2}, 573.68, 395.96);
  // p2 = 0.02 instead: xd = 0.204 + p2 (r^2 + 2 x^2) = 0.204 + 0.02 * 0.28 = 0.2096,
  // yd = 0.408 + 2 p2 x y = 0.408 + 0.0032 = 0.4112.
  const auto cam2 = CameraModel::unified(makeIntrinsics(300, 300, 512, 272), 1.0, 0.1, 0.0, 0.0, 0.02);
  expectProjects(cam2, {1, 2, 2}, 512 + 300 * 0.2096, 272 + 300 * 0.4112);
}

TEST(UnifiedModel, XiAboveOne) {
  // xi = 2: valid iff z > -d / xi = -d / 2.
  const auto cam = CameraModel::unified(makeIntrinsics(300, 300, 512, 272), 2.0);
  // (0,3,4): d = 5, z + xi d = 14 -> v = 272 + 300 * 3 / 14.
  expectProjects(cam, {0, 3, 4}, 512, 272 + 300.0 * 3.0 / 14.0);
  // (4,0,-2): d = sqrt(20) = 4.472, -2 > -2.236 so valid; denom = 2 sqrt(20) - 2.
  expectProjects(cam, {4, 0, -2}, 512 + 300.0 * 4.0 / (2.0 * std::sqrt(20.0) - 2.0), 272);
  // (4,0,-3): d = 5, -3 < -2.5: behind the valid cone.
  expectInvalid(cam, {4, 0, -3});
  // Unprojection is valid iff r^2 <= 1 / (xi^2 - 1) = 1/3. Just inside, the ray
  // is at the cone's edge: factor = (2 + sqrt(1 - 3 r^2)) / (1 + r^2) = 1.5,
  // ray = (1.5 r, 0, 1.5 - 2) = (sqrt(3)/2, 0, -1/2), i.e. 120 deg off-axis.
  Eigen::Vector3d ray;
  const double r_edge = 1.0 / std::sqrt(3.0);
  ASSERT_TRUE(cam.unproject({512 + 300 * (r_edge - 1e-12), 272}, &ray));
  EXPECT_NEAR(ray.x(), std::sqrt(3.0) / 2.0, 1e-5);
  EXPECT_NEAR(ray.z(), -0.5, 1e-5);
  EXPECT_FALSE(cam.unproject({512 + 300 * (r_edge + 1e-3), 272}, &ray));
  EXPECT_FALSE(cam.unproject({512, 272 - 300 * (r_edge + 1e-3)}, &ray));
}

TEST(UnifiedModel, ValidConeMatchesClosedForm) {
  // Without distortion the valid cone's half angle is acos(-xi) for xi <= 1
  // and acos(-1/xi) for xi > 1.
  for (double xi : {0.0, 0.5, 0.8, 1.3, 2.0, 2.8}) {
    const auto cam = CameraModel::unified(makeIntrinsics(300, 300, 512, 272), xi);
    const double expected = xi <= 1.0 ? std::acos(-xi) : std::acos(-1.0 / xi);
    EXPECT_NEAR(cam.maxValidAngle(), expected, 1e-6) << "xi " << xi;
  }
}

TEST(DoubleSphereModel, HandComputed) {
  // xi = 0, alpha = 0.5: k = z, d2 = d, norm = (d + z) / 2.
  const auto cam = CameraModel::doubleSphere(makeIntrinsics(300, 300, 512, 272), 0.0, 0.5);
  // (1,2,2): d = 3, norm = 2.5, m = (0.4, 0.8) -> (632, 512).
  expectProjects(cam, {1, 2, 2}, 632, 512);
  expectProjects(cam, {0, 0, 5}, 512, 272);
  // xi = 0.5, alpha = 0.5, (3,0,4): d1 = 5, k = 0.5 * 5 + 4 = 6.5,
  // d2 = sqrt(9 + 42.25), norm = 0.5 d2 + 0.5 * 6.5.
  const auto cam2 = CameraModel::doubleSphere(makeIntrinsics(300, 300, 512, 272), 0.5, 0.5);
  expectProjects(cam2, {3, 0, 4}, 512 + 300 * 3.0 / (0.5 * std::sqrt(51.25) + 3.25), 272);
  // alpha = 0.6, xi = 0.5: w1 = 0.4/0.6, w2 = (w1 + xi) / sqrt(2 w1 xi + xi^2 + 1)
  // = 0.8427: valid iff z > -0.8427 d.
  const auto cam3 = CameraModel::doubleSphere(makeIntrinsics(300, 300, 512, 272), 0.5, 0.6);
  const double w1 = 0.4 / 0.6;
  const double w2 = (w1 + 0.5) / std::sqrt(2 * w1 * 0.5 + 0.25 + 1.0);
  EXPECT_NEAR(cam3.maxValidAngle(), std::acos(-w2), 1e-6);
  expectInvalid(cam3, {0, 0, -1});
  expectInvalid(cam3, {0.5, 0, -1});  // 153 deg > 147 deg
  Eigen::Vector2d uv;
  EXPECT_TRUE(cam3.project({1, 0, -0.5}, &uv));  // 117 deg
  // Unprojection valid iff r^2 <= 1 / (2 alpha - 1) = 5 (alpha = 0.6).
  Eigen::Vector3d ray;
  EXPECT_TRUE(cam3.unproject({512 + 300 * 2.2, 272}, &ray));   // r^2 = 4.84
  EXPECT_FALSE(cam3.unproject({512 + 300 * 2.3, 272}, &ray));  // r^2 = 5.29
}

TEST(KannalaBrandtModel, HandComputed) {
  // Equidistant without distortion: r = f theta.
  const auto cam = CameraModel::kannalaBrandt(makeIntrinsics(300, 300, 512, 272));
  // (1,0,0): theta = pi/2 -> u = 512 + 300 pi / 2.
  expectProjects(cam, {1, 0, 0}, 512 + 150 * M_PI, 272);
  // (0,-1,1): theta = pi/4, towards -y -> v = 272 - 75 pi.
  expectProjects(cam, {0, -1, 1}, 512, 272 - 75 * M_PI);
  // (1,0,-1): theta = 3 pi / 4, beyond 90 deg.
  expectProjects(cam, {1, 0, -1}, 512 + 225 * M_PI, 272);
  // k1 = 0.1, (1,0,1): theta = pi/4, theta_d = theta (1 + 0.1 theta^2).
  const auto cam2 = CameraModel::kannalaBrandt(makeIntrinsics(300, 300, 512, 272), 0.1);
  const double t = M_PI / 4;
  expectProjects(cam2, {1, 0, 1}, 512 + 300 * t * (1 + 0.1 * t * t), 272);
  // k1 = -0.1: d theta_d / d theta = 1 - 0.3 t^2 = 0 at t = sqrt(1/0.3) = 1.826:
  // the model is valid only up to there.
  const auto cam3 = CameraModel::kannalaBrandt(makeIntrinsics(300, 300, 512, 272), -0.1);
  EXPECT_NEAR(cam3.maxValidAngle(), std::sqrt(1.0 / 0.3), 1e-6);
  expectInvalid(cam3, {std::sin(1.9), 0, std::cos(1.9)});
  // The back axis has no direction in the image.
  expectInvalid(cam, {0, 0, -1});
}

TEST(PinholeModel, HandComputed) {
  const auto cam = CameraModel::pinhole(makeIntrinsics(400, 410, 320, 240, 640, 480));
  // (1,2,10): x = 0.1, y = 0.2 -> (320 + 40, 240 + 82).
  expectProjects(cam, {1, 2, 10}, 360, 322);
  // k1 = -0.2, p2 = 0.01, same point: r^2 = 0.05, radial = 0.99;
  // xd = 0.099 + p2 (r^2 + 2 x^2) = 0.099 + 0.0007 = 0.0997;
  // yd = 0.198 + 2 p2 x y = 0.198 + 0.0004 = 0.1984;
  // u = 320 + 400 * 0.0997 = 359.88, v = 240 + 410 * 0.1984 = 321.344.
  const auto cam2 = CameraModel::pinhole(makeIntrinsics(400, 410, 320, 240, 640, 480), -0.2, 0, 0, 0.01);
  expectProjects(cam2, {1, 2, 10}, 359.88, 321.344);
  // Skew: u = fx x + skew y + cx.
  auto in = makeIntrinsics(400, 410, 320, 240, 640, 480);
  in.skew = 5.0;
  expectProjects(CameraModel::pinhole(in), {1, 2, 10}, 360 + 5 * 0.2, 322);
  expectInvalid(cam, {1, 2, 0});
  expectInvalid(cam, {1, 2, -10});
  // k1 = -0.2 alone: radial folds back at r^2 = 1 / (3 * 0.2) = 5/3.
  const auto cam3 = CameraModel::pinhole(makeIntrinsics(400, 410, 320, 240, 640, 480), -0.2);
  EXPECT_NEAR(cam3.maxValidAngle(), std::atan(std::sqrt(5.0 / 3.0)), 1e-6);
}

TEST(CameraModel, RejectsBadParameters) {
  EXPECT_THROW(CameraModel::unified(makeIntrinsics(-1, 300, 512, 272), 1.0), std::invalid_argument);
  EXPECT_THROW(CameraModel::unified(makeIntrinsics(300, 0, 512, 272), 1.0), std::invalid_argument);
  EXPECT_THROW(CameraModel::unified(makeIntrinsics(300, 300, NAN, 272), 1.0), std::invalid_argument);
  EXPECT_THROW(CameraModel::unified(makeIntrinsics(300, 300, 512, 272), -0.1), std::invalid_argument);
  EXPECT_THROW(CameraModel::doubleSphere(makeIntrinsics(300, 300, 512, 272), 0.0, 1.2),
               std::invalid_argument);
  EXPECT_THROW(CameraModel::doubleSphere(makeIntrinsics(300, 300, 512, 272), 0.0, -0.1),
               std::invalid_argument);
  EXPECT_THROW(CameraModel::kannalaBrandt(makeIntrinsics(300, 300, 512, 272, 0, 544)),
               std::invalid_argument);
  EXPECT_THROW(CameraModel::pinhole(makeIntrinsics(300, 300, 512, 272), INFINITY),
               std::invalid_argument);
  try {
    CameraModel::unified(makeIntrinsics(300, -3, 512, 272), 1.0);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("fy"), std::string::npos) << e.what();
  }
}

TEST(CameraModel, RejectsAbsurdParametersNamingThem) {
  const auto error = [](const std::function<void()>& f) -> std::string {
    try {
      f();
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "(accepted)";
  };
  EXPECT_EQ(error([] { CameraModel::unified(makeIntrinsics(1e300, 300, 512, 272), 1.0); }),
            "fx must lie in (0, 1e+06] pixels, got 1e+300");
  EXPECT_EQ(error([] { CameraModel::pinhole(makeIntrinsics(300, 2e6, 512, 272)); }),
            "fy must lie in (0, 1e+06] pixels, got 2e+06");
  EXPECT_EQ(error([] { CameraModel::pinhole(makeIntrinsics(300, 300, 512, 272, 100000, 100000)); }),
            "resolution must be at most 20000x20000 pixels, got 100000x100000");
  EXPECT_EQ(error([] { CameraModel::pinhole(makeIntrinsics(300, 300, -1e9, 272)); }),
            "cx must lie in [-1e+06, 1e+06], got -1e+09");
  EXPECT_EQ(error([] { CameraModel::pinhole(makeIntrinsics(300, 300, 512, 272), 5e3); }),
            "k1 must lie in [-1000, 1000], got 5000");
  EXPECT_EQ(error([] { CameraModel::kannalaBrandt(makeIntrinsics(300, 300, 512, 272), 0, 0, 0, -1e7); }),
            "k4 must lie in [-1000, 1000], got -1e+07");
  EXPECT_EQ(error([] { CameraModel::unified(makeIntrinsics(300, 300, 512, 272), 1e4); }),
            "xi must be at most 1000, got 10000");
  // The limits themselves are cameras.
  EXPECT_NO_THROW(CameraModel::pinhole(makeIntrinsics(1e6, 1e6, 0, 0, 20000, 20000)));
  const auto cam = CameraModel::unified(makeIntrinsics(300, 300, 512, 272), 1.0);
  EXPECT_THROW(cam.scaled(100.0, 102400, 54400), std::invalid_argument);
}

TEST(CameraModel, NonFiniteAndHugePointsDoNotProject) {
  // 1e155 squared overflows: the old code divided by infinity and returned the
  // principal point as a valid pixel.
  for (const auto& [name, cam] : test::realisticCameras()) {
    SCOPED_TRACE(name);
    Eigen::Vector2d uv;
    EXPECT_FALSE(cam.project({1e155, 1e155, 1e155}, &uv));
    EXPECT_FALSE(cam.project({0, 0, 1e31}, &uv));
    EXPECT_FALSE(cam.project({NAN, 0, 1}, &uv));
    EXPECT_FALSE(cam.project({0, INFINITY, 1}, &uv));
    EXPECT_FALSE(cam.project({0, 0, 0}, &uv));
    // Far but sane, and tiny: the same pixel as at 1 m (the models depend on the direction).
    Eigen::Vector2d near, far, tiny;
    ASSERT_TRUE(cam.project({0.1, -0.05, 1.0}, &near));
    ASSERT_TRUE(cam.project({0.1e20, -0.05e20, 1.0e20}, &far));
    ASSERT_TRUE(cam.project({0.1e-200, -0.05e-200, 1.0e-200}, &tiny));
    EXPECT_LT((near - far).norm(), 1e-9);
    EXPECT_LT((near - tiny).norm(), 1e-9);
    Eigen::Vector3d ray;
    EXPECT_FALSE(cam.unproject({NAN, 1}, &ray));
    EXPECT_FALSE(cam.unproject({1, INFINITY}, &ray));
  }
}

// ---------------------------------------------------------------------------
// Round trips over the whole valid field of view.

class RoundTrip : public ::testing::TestWithParam<int> {
 protected:
  std::pair<std::string, CameraModel> camera() const {
    return test::realisticCameras()[GetParam()];
  }
};

TEST_P(RoundTrip, RaysOverTheValidFieldOfView) {
  const auto [name, cam] = camera();
  const double max_angle = cam.maxValidAngle();
  const double w = cam.width(), h = cam.height();
  int checked = 0, beyond_90 = 0;
  for (int i = 0; i <= 200; ++i) {
    // Up to the edge of the valid cone (or nearly the back axis).
    const double theta = std::min(max_angle, M_PI) * (1.0 - 1e-4) * i / 200.0;
    for (int j = 0; j < 24; ++j) {
      const double phi = 2.0 * M_PI * j / 24.0 + 0.1;
      const Eigen::Vector3d dir(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                                std::cos(theta));
      Eigen::Vector2d uv;
      ASSERT_TRUE(cam.project(3.7 * dir, &uv)) << name << " theta " << theta;
      // Pixel coordinates far outside the image (pinhole near 90 deg) carry no
      // meaningful sub-micro-pixel precision; the check covers 3x the image.
      if (std::abs(uv.x() - w / 2) > 1.5 * w || std::abs(uv.y() - h / 2) > 1.5 * h) continue;
      Eigen::Vector3d ray;
      ASSERT_TRUE(cam.unproject(uv, &ray)) << name << " theta " << theta;
      EXPECT_NEAR(ray.norm(), 1.0, 1e-12);
      EXPECT_LT((ray - dir).norm(), 1e-9) << name << " theta " << theta << " phi " << phi;
      Eigen::Vector2d uv2;
      ASSERT_TRUE(cam.project(ray, &uv2));
      EXPECT_LT((uv2 - uv).norm(), 1e-6) << name << " theta " << theta << " phi " << phi;
      ++checked;
      beyond_90 += theta > M_PI / 2;
    }
  }
  EXPECT_GT(checked, 1000) << name;
  if (cam.type() != CameraModelType::kPinhole) {
    EXPECT_GT(beyond_90, 0) << name << ": no ray beyond 90 deg was checked";
  }
}

TEST_P(RoundTrip, PixelsOfTheImage) {
  const auto [name, cam] = camera();
  int valid = 0, total = 0;
  for (int v = 0; v < cam.height(); v += 5) {
    for (int u = 0; u < cam.width(); u += 5) {
      ++total;
      const Eigen::Vector2d uv(u + 0.25, v + 0.75);
      Eigen::Vector3d ray;
      if (!cam.unproject(uv, &ray)) continue;
      ++valid;
      Eigen::Vector2d uv2;
      ASSERT_TRUE(cam.project(ray, &uv2)) << name << " " << uv.transpose();
      EXPECT_LT((uv2 - uv).norm(), 1e-6) << name << " " << uv.transpose();
    }
  }
  // Every model here covers at least most of its image.
  EXPECT_GT(valid, total * 0.8) << name;
}

TEST_P(RoundTrip, PointsBeyondTheValidConeAreInvalid) {
  const auto [name, cam] = camera();
  const double max_angle = cam.maxValidAngle();
  if (max_angle >= M_PI - 1e-3) {
    // Valid everywhere but the back axis.
    Eigen::Vector2d uv;
    EXPECT_FALSE(cam.project({0, 0, -1}, &uv)) << name;
    return;
  }
  for (int j = 0; j < 24; ++j) {
    const double phi = 2.0 * M_PI * j / 24.0;
    for (double theta = max_angle + 0.01; theta <= M_PI; theta += 0.1) {
      const Eigen::Vector3d dir(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                                std::cos(theta));
      Eigen::Vector2d uv;
      EXPECT_FALSE(cam.project(dir, &uv)) << name << " theta " << theta << " phi " << phi;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(AllModels, RoundTrip,
                         ::testing::Range(0, static_cast<int>(test::realisticCameras().size())),
                         [](const ::testing::TestParamInfo<int>& info) {
                           std::string n = test::realisticCameras()[info.param].first;
                           for (char& c : n) {
                             if (!isalnum(static_cast<unsigned char>(c))) c = '_';
                           }
                           return n;
                         });

}  // namespace
}  // namespace fisheye_mapping
