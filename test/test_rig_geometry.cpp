// Rig geometry: fields of view and pairwise overlap, checked against numbers
// worked out by hand for small hand-built cameras and rigs (comments show the
// arithmetic), plus invariants that a wrong transform or sampling would break.
//
// Many overlap cases sample a one-row camera (height 1, cy = 0, step 1): every
// ray then lies in the camera's x-z plane, a yaw about the optical y axis keeps
// it there, and whether a sample is seen depends on its column alone. The
// camera that has to see those rays is the same camera three rows high (cy = 1),
// so that rounding in the pose (y_b = +-1e-17) cannot push them off its image.
#include <cmath>

#include <algorithm>
#include <string>

#include <gtest/gtest.h>

#include "fisheye_mapping/core/camera/rig_geometry.h"
#include "test_utils.h"

namespace fisheye_mapping {
namespace {

using test::makeIntrinsics;

constexpr double kDeg = M_PI / 180.0;
constexpr double kTol = 1e-9;  // degrees, for undistorted (exactly invertible) models

RigCamera rigCamera(const CameraModel& model, const Eigen::Isometry3d& T_cam0_cam,
                    const std::string& name = "cam") {
  RigCamera cam;
  cam.name = name;
  cam.frame_id = name;
  cam.model = model;
  cam.T_cam0_cam = T_cam0_cam;
  return cam;
}

// Rotation about the optical y axis (down): the camera's axis turns from z
// towards +x (right) by `deg`, i.e. T_cam0_cam * e_z = (sin, 0, cos).
Eigen::Isometry3d yaw(double deg) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(deg * kDeg, Eigen::Vector3d::UnitY()).toRotationMatrix();
  return T;
}

Eigen::Isometry3d translation(double x, double y, double z) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

// A camera of `width` columns and `rows` rows (1 or 3), principal point on the
// middle row: (cx, (rows - 1) / 2).
CameraModel rowPinhole(double f, double cx, int width, int rows = 1) {
  return CameraModel::pinhole(makeIntrinsics(f, f, cx, 0.5 * (rows - 1), width, rows));
}
CameraModel rowEquidistant(double f, double cx, int width, int rows = 1) {
  return CameraModel::kannalaBrandt(makeIntrinsics(f, f, cx, 0.5 * (rows - 1), width, rows));
}

// ===========================================================================
// computeFieldOfView

// Undistorted pinhole, principal point off centre. Column u has azimuth
// atan((u - cx) / fx), row v elevation atan((v - cy) / fy).
TEST(FieldOfView, PinholeOffCentreHandComputed) {
  // 501 x 201, fx 100, fy 50, principal point (100, 100).
  const auto cam = CameraModel::pinhole(makeIntrinsics(100, 50, 100, 100, 501, 201));
  const FieldOfView fov = computeFieldOfView(cam);
  // Left edge u = 0: atan(-1) = -45 deg; right edge u = 500: atan(4) = 75.964 deg.
  EXPECT_NEAR(fov.horizontal_deg, 45.0 + std::atan(4.0) / kDeg, kTol);  // 120.964
  // Rows 0 and 200: atan(-100/50), atan(100/50): 2 atan(2) = 126.870 deg.
  EXPECT_NEAR(fov.vertical_deg, 2.0 * std::atan(2.0) / kDeg, kTol);
  // Farthest pixel is the corner (500, 0) (on the even sampling grid):
  // normalized (4, -2), r = sqrt(20): atan(sqrt(20)) = 77.396 deg.
  EXPECT_NEAR(fov.max_off_axis_deg, std::atan(std::sqrt(20.0)) / kDeg, kTol);
}

TEST(FieldOfView, PinholeNinetyDegrees) {
  // fx = cx = (W - 1) / 2: the edge columns are at +-45 deg.
  const auto cam = CameraModel::pinhole(makeIntrinsics(320, 240, 320, 240, 641, 481));
  const FieldOfView fov = computeFieldOfView(cam);
  EXPECT_NEAR(fov.horizontal_deg, 90.0, kTol);
  EXPECT_NEAR(fov.vertical_deg, 90.0, kTol);
  // Corner: normalized (1, 1): atan(sqrt 2) = 54.7356 deg.
  EXPECT_NEAR(fov.max_off_axis_deg, std::atan(std::sqrt(2.0)) / kDeg, kTol);
}

// Equidistant fisheye (Kannala-Brandt, k = 0): angle off axis = radius / f.
// Wider than 180 deg: the span must not wrap or fold.
TEST(FieldOfView, EquidistantBeyondHemisphere) {
  // 1001 x 601, centre (500, 300), f chosen so that 500 px = 100 deg.
  const double f = 500.0 / (100.0 * kDeg);  // 286.479 px/rad
  const auto cam = CameraModel::kannalaBrandt(makeIntrinsics(f, f, 500, 300, 1001, 601));
  const FieldOfView fov = computeFieldOfView(cam);
  EXPECT_NEAR(fov.horizontal_deg, 200.0, kTol);  // -100 .. +100 deg
  EXPECT_NEAR(fov.vertical_deg, 120.0, kTol);    // 300 px = 60 deg each way
  // Corner (0, 0): radius sqrt(500^2 + 300^2) = 583.095 px = 116.619 deg.
  EXPECT_NEAR(fov.max_off_axis_deg, std::hypot(500.0, 300.0) / 5.0, kTol);
}

// The same model with an image wider than the whole sphere: pixels past 180 deg
// are outside the domain and must not count.
TEST(FieldOfView, EquidistantClippedAtDomain) {
  // 1 px = 1 deg, cx = 200.5: columns at -200.5 .. 199.5 deg in 1 deg steps;
  // the valid ones (|angle| <= 180) run from u = 21 (-179.5) to u = 380 (179.5).
  const auto cam = rowEquidistant(180.0 / M_PI, 200.5, 401);
  const FieldOfView fov = computeFieldOfView(cam);
  EXPECT_NEAR(fov.horizontal_deg, 359.0, 1e-7);
  // One row: the centre column holds the single axis ray.
  EXPECT_NEAR(fov.vertical_deg, 0.0, kTol);
  // Even columns only: u = 380 (179.5 deg) is the farthest valid one (u = 20
  // is at 180.5 deg, outside).
  EXPECT_NEAR(fov.max_off_axis_deg, 179.5, 1e-7);
}

// Unified model with xi = 1: the normalized radius is tan(theta / 2).
TEST(FieldOfView, UnifiedXiOneIsStereographic) {
  // 1201 x 601, centre (600, 300), f 300: edge radii 2 and 1.
  const auto cam = CameraModel::unified(makeIntrinsics(300, 300, 600, 300, 1201, 601), 1.0);
  const FieldOfView fov = computeFieldOfView(cam);
  EXPECT_NEAR(fov.horizontal_deg, 4.0 * std::atan(2.0) / kDeg, kTol);  // 253.74 deg
  EXPECT_NEAR(fov.vertical_deg, 180.0, kTol);                          // 4 atan(1)
  EXPECT_NEAR(fov.max_off_axis_deg, 2.0 * std::atan(std::sqrt(5.0)) / kDeg, kTol);
}

// Angle theta off the axis of the unified model's ray through normalized
// radius m, found from the forward model m = sin(theta) / (cos(theta) + xi),
// increasing on [0, acos(-1/xi)] for xi > 1 (bisection, independent of the
// library's closed-form inverse).
double unifiedTheta(double xi, double m) {
  double lo = 0.0, hi = std::acos(-1.0 / xi);
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (std::sin(mid) / (std::cos(mid) + xi) < m ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

// Unified model with xi = 2: only pixels with r^2 <= 1 / (xi^2 - 1) = 1/3
// unproject; the corners of the image are outside that disc.
TEST(FieldOfView, UnifiedXiTwoExcludesPixelsOutsideDomain) {
  // 201 x 201, centre (100, 100), f 100: r = offset / 100, r_max = 0.57735.
  const auto cam = CameraModel::unified(makeIntrinsics(100, 100, 100, 100, 201, 201), 2.0);
  const FieldOfView fov = computeFieldOfView(cam);
  // Centre row / column: extreme valid offsets +-57 px (r = 0.57).
  const double theta_row = unifiedTheta(2.0, 0.57) / kDeg;  // 111.7 deg
  EXPECT_NEAR(fov.horizontal_deg, 2.0 * theta_row, 1e-7);
  EXPECT_NEAR(fov.vertical_deg, 2.0 * theta_row, 1e-7);
  // Even grid: offsets (2a, 2b) with 4 (a^2 + b^2) <= 3333.3; the largest sum
  // of two squares <= 833 is 833 = 28^2 + 7^2, so r^2 = 3332 / 10000.
  EXPECT_NEAR(fov.max_off_axis_deg, unifiedTheta(2.0, std::sqrt(0.3332)) / kDeg, 1e-7);
  // Never beyond the domain's edge acos(-1/xi) = 120 deg.
  EXPECT_LT(fov.max_off_axis_deg, 120.0);
}

TEST(FieldOfView, NoValidPixelGivesZero) {
  // xi = 2 again, but the principal point 1000 px left of the image (a crop
  // of the image plane far right of it: a calibration saying so is refused):
  // every pixel has r >= 10 > 0.577, so none unprojects.
  const auto cam = CameraModel::unified(makeIntrinsics(100, 100, 50, 50, 100, 100), 2.0).cropped(1050, 0, 100, 100);
  Eigen::Vector3d ray;
  ASSERT_FALSE(cam.unproject(Eigen::Vector2d(99, 50), &ray));  // the nearest pixel
  const FieldOfView fov = computeFieldOfView(cam);
  EXPECT_EQ(fov.horizontal_deg, 0.0);
  EXPECT_EQ(fov.max_off_axis_deg, 0.0);
}

// The vertical span is scanned along the image column nearest the principal
// point, so points that are not pixels of the image never count: for the
// camera above, whose image has no valid pixel at all, it once reported
// 177.8 deg (scanned along u = cx, outside the image). The same for the
// horizontal span when cy lies outside the image.
TEST(FieldOfView, VerticalSpanIgnoresPointsOutsideImage) {
  const auto cam = CameraModel::unified(makeIntrinsics(100, 100, 50, 50, 100, 100), 2.0).cropped(1050, 0, 100, 100);
  EXPECT_EQ(computeFieldOfView(cam).vertical_deg, 0.0);
  // Transposed: principal point below the image, the horizontal span.
  const auto cam_t = CameraModel::unified(makeIntrinsics(100, 100, 50, 50, 100, 100), 2.0).cropped(0, 1050, 100, 100);
  EXPECT_EQ(computeFieldOfView(cam_t).horizontal_deg, 0.0);
}

// Realistic cameras: every valid ray lies in the model's domain cone, so no
// angle can exceed maxValidAngle(), and every such camera sees something.
TEST(FieldOfView, RealisticCamerasWithinDomain) {
  for (const auto& [name, cam] : test::realisticCameras()) {
    SCOPED_TRACE(name);
    const FieldOfView fov = computeFieldOfView(cam);
    const double max_deg = cam.maxValidAngle() / kDeg;
    EXPECT_GT(fov.horizontal_deg, 0.0);
    EXPECT_GT(fov.vertical_deg, 0.0);
    EXPECT_GT(fov.max_off_axis_deg, 0.0);
    EXPECT_LE(fov.max_off_axis_deg, max_deg + 1e-6);
    EXPECT_LE(fov.horizontal_deg, 2.0 * max_deg + 1e-6);
    EXPECT_LE(fov.vertical_deg, 2.0 * max_deg + 1e-6);
  }
}

// ===========================================================================
// computeOverlap

TEST(Overlap, CameraWithItselfIsOne) {
  for (const auto& [name, model] : test::realisticCameras()) {
    SCOPED_TRACE(name);
    const RigCamera a = rigCamera(model, translation(0.3, -0.2, 1.5) * yaw(37.0));
    EXPECT_DOUBLE_EQ(computeOverlap(a, a), 1.0);
    // Step 5 (samples from 2): no sample on the last row or column of these
    // sizes, where the round trip may land 1e-10 px outside the image.
    EXPECT_DOUBLE_EQ(computeOverlap(a, a, 0.5, 5), 1.0);
  }
}

// b is the left or right half of a's image (same pose, cropped intrinsics).
TEST(Overlap, CroppedHalvesSeeHalf) {
  const CameraModel full = test::realisticCameras()[0].second;  // pinhole 640 x 480, radtan
  ASSERT_EQ(full.width(), 640);
  const RigCamera a = rigCamera(full, Eigen::Isometry3d::Identity());
  const RigCamera left = rigCamera(full.cropped(0, 0, 320, 480), Eigen::Isometry3d::Identity());
  const RigCamera right = rigCamera(full.cropped(320, 0, 320, 480), Eigen::Isometry3d::Identity());
  // step 8: columns 4, 12, ..., 636 (80), rows 4 ... 476 (60); columns <= 316
  // fall in the left half, >= 324 in the right one (u - 320 in [4, 316]).
  EXPECT_DOUBLE_EQ(computeOverlap(a, left), 0.5);
  EXPECT_DOUBLE_EQ(computeOverlap(a, right), 0.5);
  // Every pixel of a half is a pixel of the full image.
  EXPECT_DOUBLE_EQ(computeOverlap(left, a), 1.0);
  EXPECT_DOUBLE_EQ(computeOverlap(right, a), 1.0);
  // The halves share no pixel.
  EXPECT_DOUBLE_EQ(computeOverlap(left, right), 0.0);
}

// Which pixels are sampled: a is 10 x 4, b's image is a's shifted by half a
// pixel (u_b = u_a - 0.5, v_b = v_a + 2) and 5 columns wide, so a's column u
// is seen iff 0.5 <= u <= 4.5, i.e. u in {1, 2, 3, 4}; every row is seen.
TEST(Overlap, StepSamplesCellCentres) {
  const RigCamera a =
      rigCamera(CameraModel::pinhole(makeIntrinsics(100, 100, 4.5, 1.5, 10, 4)),
                Eigen::Isometry3d::Identity());
  const RigCamera b =
      rigCamera(CameraModel::pinhole(makeIntrinsics(100, 100, 4.0, 3.5, 5, 10)),
                Eigen::Isometry3d::Identity());
  EXPECT_DOUBLE_EQ(computeOverlap(a, b, 20.0, 1), 4.0 / 10.0);  // every pixel
  // Cell centres step/2, step/2 + step, ...:
  EXPECT_DOUBLE_EQ(computeOverlap(a, b, 20.0, 2), 2.0 / 5.0);  // u 1 3 5 7 9
  EXPECT_DOUBLE_EQ(computeOverlap(a, b, 20.0, 3), 2.0 / 3.0);  // u 1 4 7
  EXPECT_DOUBLE_EQ(computeOverlap(a, b, 20.0, 4), 1.0 / 2.0);  // u 2 6
  EXPECT_DOUBLE_EQ(computeOverlap(a, b, 20.0, 5), 1.0 / 2.0);  // u 2 7
}

// Pure rotation, pinhole row cameras, f 100. a: cx = 50 (azimuths
// atan(-0.5) = -26.57 .. atan(1.5) = 56.31 deg); b: cx = 100 (+-45 deg), its
// axis turned 30 deg to the right of a's. A ray at azimuth phi in a is at
// phi - 30 in b.
class RotatedPair : public ::testing::Test {
 protected:
  // Source of the samples (one row) and target (three rows) of each camera.
  RigCamera a(const Eigen::Isometry3d& T = Eigen::Isometry3d::Identity()) const {
    return rigCamera(rowPinhole(100, 50, 201), T, "a");
  }
  RigCamera a3(const Eigen::Isometry3d& T = Eigen::Isometry3d::Identity()) const {
    return rigCamera(rowPinhole(100, 50, 201, 3), T, "a");
  }
  RigCamera b(const Eigen::Isometry3d& T = yaw(30.0)) const {
    return rigCamera(rowPinhole(100, 100, 201), T, "b");
  }
  RigCamera b3(const Eigen::Isometry3d& T = yaw(30.0)) const {
    return rigCamera(rowPinhole(100, 100, 201, 3), T, "b");
  }
};

TEST_F(RotatedPair, HandComputedBothWays) {
  // a -> b: seen iff phi - 30 >= -45, i.e. u >= 50 + 100 tan(-15 deg) = 23.2:
  // u = 24 .. 200, 177 of 201. (With the rotation applied the wrong way round,
  // phi + 30 <= 45: u <= 76.8, 77 of 201.)
  EXPECT_DOUBLE_EQ(computeOverlap(a(), b3(), 20.0, 1), 177.0 / 201.0);
  // b -> a: seen iff psi + 30 <= atan(1.5), i.e. tan(psi) <= (1.5 - 1/sqrt3) /
  // (1 + 1.5/sqrt3) = 0.49445: u <= 149.4, u = 0 .. 149, 150 of 201.
  EXPECT_DOUBLE_EQ(computeOverlap(b(), a3(), 20.0, 1), 150.0 / 201.0);
}

TEST_F(RotatedPair, RangeDoesNotMatterWithoutBaseline) {
  for (double range : {0.01, 1.0, 20.0, 1e5}) {
    SCOPED_TRACE(range);
    EXPECT_DOUBLE_EQ(computeOverlap(a(), b3(), range, 1), 177.0 / 201.0);
    EXPECT_DOUBLE_EQ(computeOverlap(b(), a3(), range, 1), 150.0 / 201.0);
  }
}

// Only the relative pose matters: moving the whole rig (both T_cam0_cam by the
// same G) changes nothing.
TEST_F(RotatedPair, InvariantUnderCommonReferenceChange) {
  Eigen::Isometry3d G = Eigen::Isometry3d::Identity();
  G.linear() = (Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()) *
                Eigen::AngleAxisd(-1.9, Eigen::Vector3d::UnitZ()))
                   .toRotationMatrix();
  G.translation() = Eigen::Vector3d(12.5, -3.0, 0.75);
  // Sanity of the fixture itself: composing with the inverse is the identity.
  EXPECT_LT(((G.inverse() * G).matrix() - Eigen::Matrix4d::Identity()).norm(), 1e-12);
  EXPECT_DOUBLE_EQ(computeOverlap(a(G), b3(G * yaw(30.0)), 20.0, 1), 177.0 / 201.0);
  EXPECT_DOUBLE_EQ(computeOverlap(b(G * yaw(30.0)), a3(G), 20.0, 1), 150.0 / 201.0);
}

// Cameras turned away from each other: pinhole (+-45 deg) images share nothing
// at 100 deg or 180 deg (pinhole b cannot see behind itself).
TEST(Overlap, TurnedAwaySeeNothing) {
  const auto model = CameraModel::pinhole(makeIntrinsics(320, 320, 320, 240, 641, 481));
  const RigCamera a = rigCamera(model, Eigen::Isometry3d::Identity());
  for (double deg : {100.0, -100.0, 180.0}) {
    SCOPED_TRACE(deg);
    const RigCamera b = rigCamera(model, yaw(deg));
    EXPECT_DOUBLE_EQ(computeOverlap(a, b), 0.0);
    EXPECT_DOUBLE_EQ(computeOverlap(b, a), 0.0);
  }
}

// Sideways baseline: b 1 m to the right of a, same orientation, pinhole rows
// f 100, cx 100 (+-45 deg). Column u has normalized n = (u - 100) / 100; its
// point at range R is R (n, 0, 1) / s, s = sqrt(1 + n^2), and lands in b at
// u_b = u - 100 s / R.
TEST(Overlap, SidewaysBaselineParallax) {
  const Eigen::Isometry3d T_cam0_b = translation(1.0, 0.0, 0.0);
  const RigCamera a = rigCamera(rowPinhole(100, 100, 201), Eigen::Isometry3d::Identity());
  const RigCamera a3 = rigCamera(rowPinhole(100, 100, 201, 3), Eigen::Isometry3d::Identity());
  const RigCamera b = rigCamera(rowPinhole(100, 100, 201), T_cam0_b);
  const RigCamera b3 = rigCamera(rowPinhole(100, 100, 201, 3), T_cam0_b);
  // R = 10: seen iff u >= 10 s. u = 14: 10 sqrt(1.7396) = 13.19 (seen);
  // u = 13: 10 sqrt(1.7569) = 13.25 (not): u = 14 .. 200, 187 of 201.
  EXPECT_DOUBLE_EQ(computeOverlap(a, b3, 10.0, 1), 187.0 / 201.0);
  // Mirror image the other way: u_a = u_b + 10 s <= 200 iff u_b <= 186.
  EXPECT_DOUBLE_EQ(computeOverlap(b, a3, 10.0, 1), 187.0 / 201.0);
  // R = 1e6: the shift is at most 1.4e-4 px, so only column 0 leaves b.
  EXPECT_DOUBLE_EQ(computeOverlap(a, b3, 1e6, 1), 200.0 / 201.0);
  // Farther points have less parallax: the share never falls with range.
  double previous = 0.0;
  for (double range : {1.0, 2.0, 5.0, 10.0, 50.0, 1000.0}) {
    const double o = computeOverlap(a, b3, range, 1);
    EXPECT_GE(o, previous) << range;
    EXPECT_GE(o, 0.0);
    EXPECT_LE(o, 1.0);
    previous = o;
  }
  // R = 2: seen iff 100 + 100 n >= 50 s, i.e. 3 n^2 + 8 n + 3 >= 0, i.e.
  // n >= (-8 + sqrt 28) / 6 = -0.4514: u >= 54.86, u = 55 .. 200, 146 of 201.
  EXPECT_DOUBLE_EQ(computeOverlap(a, b3, 2.0, 1), 146.0 / 201.0);
}

// Equidistant row fisheyes, f 60 px/rad: a (cx 100) sees -5/3 .. 5/3 rad
// (+-95.5 deg), column u at azimuth (u - 100) / 60. b (cx 80) has its axis
// turned 90 deg to the right.
TEST(Overlap, FisheyeNinetyDegreeYaw) {
  const RigCamera a = rigCamera(rowEquidistant(60, 100, 201), Eigen::Isometry3d::Identity());
  const RigCamera a3 = rigCamera(rowEquidistant(60, 100, 201, 3), Eigen::Isometry3d::Identity());
  const RigCamera b = rigCamera(rowEquidistant(60, 80, 201), yaw(90.0));
  const RigCamera b3 = rigCamera(rowEquidistant(60, 80, 201, 3), yaw(90.0));
  // The yaw maps the axes as expected: b's z is cam0's x, b's x is cam0's -z.
  const Eigen::Matrix3d R = b.T_cam0_cam.linear();
  EXPECT_LT((R.col(2) - Eigen::Vector3d::UnitX()).norm(), 1e-12);
  EXPECT_LT((R.col(0) + Eigen::Vector3d::UnitZ()).norm(), 1e-12);
  EXPECT_LT((R.col(1) - Eigen::Vector3d::UnitY()).norm(), 1e-12);
  // a -> b: azimuth phi is phi - pi/2 in b, at u_b = 80 + 60 (phi - pi/2) =
  // u - 20 - 30 pi = u - 114.25 >= 0: u = 115 .. 200, 86 of 201. (Turned the
  // wrong way, u_b = u + 74.25 <= 200: 126 of 201.)
  EXPECT_DOUBLE_EQ(computeOverlap(a, b3, 20.0, 1), 86.0 / 201.0);
  // b -> a: u_a = u_b + 114.25 <= 200: u_b = 0 .. 85, 86 of 201.
  EXPECT_DOUBLE_EQ(computeOverlap(b, a3, 20.0, 1), 86.0 / 201.0);
}

// Back-to-back equidistant fisheyes, f 60 px/rad, cx 100: each sees +-100/60 =
// +-95.5 deg. The shared bands lie beyond pi - 5/3 = 1.4749 rad on each side:
// u - 100 >= 88.5, i.e. 89 .. 100 on the right and -100 .. -89 on the left.
TEST(Overlap, FisheyeBackToBack) {
  const RigCamera a = rigCamera(rowEquidistant(60, 100, 201), Eigen::Isometry3d::Identity());
  const RigCamera a3 = rigCamera(rowEquidistant(60, 100, 201, 3), Eigen::Isometry3d::Identity());
  const RigCamera b = rigCamera(rowEquidistant(60, 100, 201), yaw(180.0));
  const RigCamera b3 = rigCamera(rowEquidistant(60, 100, 201, 3), yaw(180.0));
  EXPECT_DOUBLE_EQ(computeOverlap(a, b3, 20.0, 1), 24.0 / 201.0);
  EXPECT_DOUBLE_EQ(computeOverlap(b, a3, 20.0, 1), 24.0 / 201.0);
}

TEST(Overlap, NoValidPixelGivesZero) {
  // No pixel of `dead` unprojects (see FieldOfView.NoValidPixelGivesZero).
  const RigCamera dead = rigCamera(
      CameraModel::unified(makeIntrinsics(100, 100, 50, 50, 100, 100), 2.0).cropped(1050, 0, 100, 100),
      Eigen::Isometry3d::Identity());
  const RigCamera live = rigCamera(test::realisticCameras()[1].second, Eigen::Isometry3d::Identity());
  EXPECT_EQ(computeOverlap(dead, live), 0.0);  // no sample at all
  // Whatever dead's domain holds projects far left of its image (cx = -1000).
  EXPECT_EQ(computeOverlap(live, dead), 0.0);
}

}  // namespace
}  // namespace fisheye_mapping
