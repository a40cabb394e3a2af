// CameraInfo <-> camera models and rigs: exact round trips of every model,
// hand-checked K / D / P of a known camera, each bad field named in its error,
// and a rig built from CameraInfos + poses equal to the camchain + mount one.
#include <cmath>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "fisheye_mapping/ros/camera_info.h"
#include "fisheye_mapping/ros/camera_models.h"
#include "test_utils.h"

namespace fisheye_mapping {
namespace {

// Two cameras. cam1: T_c1_c0 = [R10 | (0, 0, -0.3)], R10 = [[0,0,-1],[0,1,0],
// [1,0,0]], so cam1's axes in cam0 (the rows of R10) are x (0, 0, -1),
// y (0, 1, 0), z (1, 0, 0), and its centre -R10^T t = (0.3, 0, 0).
// Mount: cam0 -> base_link R = [[0,0,1],[-1,0,0],[0,-1,0]], t = (1.5, 0, 1.6).
const char* kCamchain = R"YAML(
cam0:
  camera_model: omni
  intrinsics: [1.1, 300.0, 301.0, 512.0, 272.0]
  distortion_model: radtan
  distortion_coeffs: [-0.3, 0.08, 0.001, -0.0005]
  resolution: [1024, 544]
cam1:
  camera_model: pinhole
  intrinsics: [330.0, 331.0, 511.5, 271.5]
  distortion_model: equidistant
  distortion_coeffs: [0.02, -0.005, 0.001, -0.0002]
  resolution: [1024, 544]
  T_cn_cnm1:
  - [0.0, 0.0, -1.0, 0.0]
  - [0.0, 1.0, 0.0, 0.0]
  - [1.0, 0.0, 0.0, -0.3]
  - [0.0, 0.0, 0.0, 1.0]
)YAML";
const char* kMount = R"YAML(
base_frame: base_link
T_base_cam0:
- [0.0, 0.0, 1.0, 1.5]
- [-1.0, 0.0, 0.0, 0.0]
- [0.0, -1.0, 0.0, 1.6]
- [0.0, 0.0, 0.0, 1.0]
frame_ids: {cam0: front_optical, cam1: right_optical}
)YAML";

Rig loadRig() { return loadKalibrRigFromStrings(kCamchain, kMount); }

// Points around the camera, each in the model's valid domain.
std::vector<Eigen::Vector3d> pointsSeenBy(const CameraModel& cam, int n) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Eigen::Vector3d> pts;
  Eigen::Vector2d uv;
  while (static_cast<int>(pts.size()) < n) {
    const Eigen::Vector3d p = Eigen::Vector3d(u(rng), u(rng), u(rng) + 0.5) * 10.0;
    if (cam.project(p, &uv) && cam.isInImage(uv)) pts.push_back(p);
  }
  return pts;
}

void expectSameProjections(const CameraModel& a, const CameraModel& b) {
  Eigen::Vector2d uv_a, uv_b;
  for (const auto& p : pointsSeenBy(a, 100)) {
    ASSERT_TRUE(a.project(p, &uv_a));
    ASSERT_TRUE(b.project(p, &uv_b)) << p.transpose();
    EXPECT_NEAR((uv_a - uv_b).norm(), 0.0, 1e-9) << p.transpose();
  }
}

TEST(CameraInfo, MeiFromCamchainRoundTripsExactly) {
  const Rig rig = loadRig();
  const CameraModel& cam = rig.cameras[0].model;
  const sensor_msgs::CameraInfo msg = toCameraInfo(rig.cameras[0], ros::Time(12, 5));
  EXPECT_EQ(msg.header.frame_id, "front_optical");
  EXPECT_EQ(msg.header.stamp, ros::Time(12, 5));
  const CameraModel back = fromCameraInfo(msg);
  EXPECT_EQ(back.type(), CameraModelType::kUnified);
  EXPECT_EQ(back.width(), 1024);
  EXPECT_EQ(back.height(), 544);
  expectSameProjections(cam, back);
}

TEST(CameraInfo, EveryModelRoundTrips) {
  for (const auto& named : test::realisticCameras()) {
    SCOPED_TRACE(named.first);
    const CameraModel back = fromCameraInfo(toCameraInfo(named.second, "f", ros::Time()));
    EXPECT_EQ(back.type(), named.second.type());
    EXPECT_EQ(back.name(), named.second.name());
    expectSameProjections(named.second, back);
  }
}

TEST(CameraInfo, HandCheckedEntriesOfTheCamchainsMeiCamera) {
  const sensor_msgs::CameraInfo msg = toCameraInfo(loadRig().cameras[0], ros::Time());
  EXPECT_EQ(msg.width, 1024u);
  EXPECT_EQ(msg.height, 544u);
  EXPECT_EQ(msg.distortion_model, "omni");
  // From the camchain: intrinsics [xi fu fv pu pv], distortion [k1 k2 p1 p2].
  const std::vector<double> D = {1.1, -0.3, 0.08, 0.001, -0.0005};
  EXPECT_EQ(msg.D, D);
  const boost::array<double, 9> K = {300, 0, 512, 0, 301, 272, 0, 0, 1};
  const boost::array<double, 9> R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  const boost::array<double, 12> P = {300, 0, 512, 0, 0, 301, 272, 0, 0, 0, 1, 0};
  EXPECT_EQ(msg.K, K);
  EXPECT_EQ(msg.R, R);
  EXPECT_EQ(msg.P, P);
  EXPECT_EQ(msg.binning_x, 0u);
  EXPECT_EQ(msg.binning_y, 0u);
  EXPECT_EQ(msg.roi.width, 0u);
  EXPECT_EQ(msg.roi.height, 0u);
  EXPECT_EQ(msg.roi.x_offset, 0u);
}

TEST(CameraInfo, StandardNamesForPinholeAndKannalaBrandt) {
  const CameraModel pin = CameraModel::pinhole(test::makeIntrinsics(400, 410, 320, 240, 640, 480),
                                               -0.28, 0.07, 1e-3, -5e-4);
  const sensor_msgs::CameraInfo a = toCameraInfo(pin, "f", ros::Time());
  EXPECT_EQ(a.distortion_model, "plumb_bob");
  EXPECT_EQ(a.D, (std::vector<double>{-0.28, 0.07, 1e-3, -5e-4, 0.0}));
  const sensor_msgs::CameraInfo b = toCameraInfo(loadRig().cameras[1], ros::Time());
  EXPECT_EQ(b.distortion_model, "equidistant");
  EXPECT_EQ(b.D, (std::vector<double>{0.02, -0.005, 0.001, -0.0002}));
  // rational_polynomial with k3..k6 = 0 is the same pinhole camera.
  sensor_msgs::CameraInfo c = a;
  c.distortion_model = "rational_polynomial";
  c.D = {-0.28, 0.07, 1e-3, -5e-4, 0, 0, 0, 0};
  expectSameProjections(pin, fromCameraInfo(c));
}

// Runs fromCameraInfo on the Mei camera's message changed by `edit` and
// expects a CalibrationError containing each of `parts`.
void expectError(const std::function<void(sensor_msgs::CameraInfo&)>& edit,
                 const std::vector<std::string>& parts) {
  sensor_msgs::CameraInfo msg = toCameraInfo(loadRig().cameras[0], ros::Time());
  edit(msg);
  try {
    fromCameraInfo(msg);
    ADD_FAILURE() << "no error; expected: " << parts[0];
  } catch (const CalibrationError& e) {
    for (const auto& part : parts) EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
  }
}

TEST(CameraInfo, EachErrorNamesItsField) {
  expectError([](auto& m) { m.distortion_model = "kalibr_omni"; },
              {"CameraInfo 'front_optical'", "distortion_model", "'kalibr_omni'",
               "plumb_bob, rational_polynomial, equidistant, omni, double_sphere"});
  expectError([](auto& m) { m.D.pop_back(); },
              {"D: expected 5 values for distortion_model 'omni' (xi, k1, k2, p1, p2), got 4"});
  expectError([](auto& m) { m.distortion_model = "plumb_bob"; },
              {"D[4] (k3): must be 0"});  // D = [1.1 ...]: five values, k3 = -0.0005
  expectError([](auto& m) { m.K[0] = -300; }, {"K[0] (fx): must be positive, got -300"});
  expectError([](auto& m) { m.K[0] = 0; }, {"K[0] (fx)", "uncalibrated"});
  expectError([](auto& m) { m.K[4] = std::nan(""); }, {"K[4]: must be finite"});
  expectError([](auto& m) { m.K[4] = 0; }, {"K[4] (fy): must be positive"});
  expectError([](auto& m) { m.width = 0; }, {"width: must be positive, got 0"});
  expectError([](auto& m) { m.height = 0; }, {"height: must be positive, got 0"});
  expectError([](auto& m) { m.D[0] = -0.5; }, {"D[0] (xi): must be >= 0, got -0.5"});
  expectError([](auto& m) { m.D[2] = INFINITY; }, {"D[2] (k2): must be finite"});
  expectError([](auto& m) { m.K[8] = 2; }, {"K: must be [fx skew cx; 0 fy cy; 0 0 1]"});
  expectError([](auto& m) { m.binning_x = 2; }, {"binning_x/binning_y", "2x0"});
  expectError([](auto& m) { m.roi.width = 100; }, {"roi"});
  expectError(
      [](auto& m) {
        m.distortion_model = "double_sphere";
        m.D = {0.1, 1.5};
      },
      {"alpha"});
}

// The camchain rig's poses, written out by hand: cam0 from the mount; cam1 at
// (0.3, 0, 0) in cam0 -> base R0 (0.3, 0, 0) + t = (1.5, -0.3, 1.6), its axes
// in cam0 (x (0, 0, -1), y (0, 1, 0), z (1, 0, 0)) mapped by R0 to
// (-1, 0, 0), (0, 0, -1), (0, -1, 0): it looks to the vehicle's right.
std::vector<CameraInfoAndPose> handMadeInfos() {
  const Rig rig = loadRig();
  Eigen::Isometry3d T0 = Eigen::Isometry3d::Identity(), T1 = Eigen::Isometry3d::Identity();
  T0.linear() << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  T0.translation() << 1.5, 0, 1.6;
  T1.linear() << -1, 0, 0, 0, 0, -1, 0, -1, 0;  // the columns above
  T1.translation() << 1.5, -0.3, 1.6;
  return {{toCameraInfo(rig.cameras[0], ros::Time()), T0, ""},
          {toCameraInfo(rig.cameras[1], ros::Time()), T1, ""}};
}

TEST(CameraInfo, RigFromCameraInfosEqualsTheCamchainRig) {
  const Rig want = loadRig();
  const Rig got = rigFromCameraInfos(handMadeInfos(), "base_link");
  ASSERT_EQ(got.cameras.size(), 2u);
  EXPECT_EQ(got.base_frame, "base_link");
  for (size_t i = 0; i < 2; ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(got.cameras[i].name, want.cameras[i].name);
    EXPECT_EQ(got.cameras[i].frame_id, want.cameras[i].frame_id);
    EXPECT_TRUE(got.cameras[i].T_cam0_cam.isApprox(want.cameras[i].T_cam0_cam, 1e-12));
    // The same base-frame points land on the same pixels through both rigs.
    const Eigen::Isometry3d T_base_cam = want.cameras[i].T_base_cam;
    int seen = 0;
    Eigen::Vector2d uv_want, uv_got;
    for (const auto& p_C : pointsSeenBy(want.cameras[i].model, 100)) {
      const Eigen::Vector3d p_B = T_base_cam * p_C;
      ASSERT_TRUE(want.cameras[i].model.project(want.cameras[i].T_base_cam.inverse() * p_B, &uv_want));
      ASSERT_TRUE(got.cameras[i].model.project(got.cameras[i].T_base_cam.inverse() * p_B, &uv_got));
      EXPECT_NEAR((uv_want - uv_got).norm(), 0.0, 1e-9);
      ++seen;
    }
    EXPECT_EQ(seen, 100);
  }
}

void expectRigError(const std::function<void(std::vector<CameraInfoAndPose>&)>& edit,
                    const std::string& part, const std::string& base = "base_link") {
  auto infos = handMadeInfos();
  edit(infos);
  try {
    rigFromCameraInfos(infos, base);
    ADD_FAILURE() << "no error; expected: " << part;
  } catch (const CalibrationError& e) {
    EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
  }
}

TEST(CameraInfo, RigErrorsNameTheCamera) {
  expectRigError([](auto& c) { c.clear(); }, "no camera");
  expectRigError([](auto&) {}, "base frame must not be empty", "");
  expectRigError([](auto& c) { c[1].info.header.frame_id = "front_optical"; },
                 "cam1: frame 'front_optical' is also cam0's");
  expectRigError([](auto& c) { c[1].info.header.frame_id = "base_link"; }, "cam1: frame 'base_link' is the base frame");
  expectRigError([](auto& c) { c[1].info.header.frame_id = ""; }, "cam1: header.frame_id must not be empty");
  expectRigError([](auto& c) { c[1].T_base_cam.linear() *= 1.1; }, "cam1: T_base_cam (base_link <- right_optical)");
  expectRigError([](auto& c) { c[1].T_base_cam.translation().x() = 1e5; }, "cam1: T_base_cam translation");
  expectRigError([](auto& c) { c[1].name = "cam0"; }, "cam0: name given to two cameras");
  expectRigError([](auto& c) { c[1].info.K[0] = -1; }, "CameraInfo 'right_optical': K[0] (fx)");
}

TEST(CameraInfo, ScaledForAHalfResolutionDepthImage) {
  const Rig rig = loadRig();  // kept: cam refers into it
  const CameraModel& cam = rig.cameras[0].model;
  const sensor_msgs::CameraInfo msg = scaledCameraInfo(cam, 0.5, "front_optical", ros::Time());
  EXPECT_EQ(msg.width, 512u);
  EXPECT_EQ(msg.height, 272u);
  // fx 300 -> 150, fy 301 -> 150.5, cx (512 + 0.5) / 2 - 0.5 = 255.75, cy (272 + 0.5) / 2 - 0.5 = 135.75.
  const boost::array<double, 9> K = {150, 0, 255.75, 0, 150.5, 135.75, 0, 0, 1};
  EXPECT_EQ(msg.K, K);
  EXPECT_EQ(msg.D, (std::vector<double>{1.1, -0.3, 0.08, 0.001, -0.0005}));  // unchanged
  // A pixel of the half image sees what the 2x2 block it came from sees:
  // full-resolution pixel centres 2u + 0.5 map to u.
  const CameraModel half = fromCameraInfo(msg);
  Eigen::Vector2d uv_full, uv_half;
  for (const auto& p : pointsSeenBy(cam, 20)) {
    ASSERT_TRUE(cam.project(p, &uv_full));
    ASSERT_TRUE(half.project(p, &uv_half));
    EXPECT_NEAR((uv_half - (uv_full - Eigen::Vector2d(0.5, 0.5)) / 2.0).norm(), 0.0, 1e-9);
  }
  // Odd sizes round down as the depth stage's W/2 x H/2.
  const CameraModel odd = CameraModel::unified(test::makeIntrinsics(300, 300, 400, 300, 801, 601), 1.0);
  const sensor_msgs::CameraInfo o = scaledCameraInfo(odd, 0.5, "f", ros::Time());
  EXPECT_EQ(o.width, 400u);
  EXPECT_EQ(o.height, 300u);
  EXPECT_THROW(scaledCameraInfo(cam, 0.0, "f", ros::Time()), std::invalid_argument);
  EXPECT_THROW(scaledCameraInfo(cam, 1e-4, "f", ros::Time()), std::invalid_argument);
}

// The one CameraInfo -> model cache (the TSDF's models by frame, the mask's
// camera of its depth): parsed again only when the calibration changes, a
// bad one refused with fromCameraInfo's error until a good one comes.
TEST(CameraInfo, ModelsByFrameFollowTheCalibration) {
  const Rig rig = loadRig();
  CameraModelsByFrame cache;
  sensor_msgs::CameraInfo front = toCameraInfo(rig.cameras[0], ros::Time(1.0));
  EXPECT_EQ(cache.find("front_optical"), nullptr);
  EXPECT_TRUE(cache.update(front));
  const auto first = cache.find("front_optical");
  ASSERT_NE(first, nullptr);
  expectSameProjections(*first, rig.cameras[0].model);
  front.header.stamp = ros::Time(2.0);  // the same calibration at another stamp: the same model
  EXPECT_FALSE(cache.update(front));
  EXPECT_EQ(cache.find("front_optical"), first);
  EXPECT_EQ(cache.find("right_optical"), nullptr);  // another frame has none yet

  sensor_msgs::CameraInfo bad = front;
  bad.K[0] = -300;
  for (int i = 0; i < 2; ++i) {  // a repeated bad one: the same error
    try {
      cache.update(bad);
      ADD_FAILURE() << "a negative fx was accepted";
    } catch (const CalibrationError& e) {
      EXPECT_NE(std::string(e.what()).find("K[0] (fx): must be positive, got -300"), std::string::npos) << e.what();
    }
  }
  EXPECT_EQ(cache.find("front_optical"), nullptr);  // no model until a good one
  front.K[2] = 500.0;                                 // cx moved 12 px: a new model
  EXPECT_TRUE(cache.update(front));
  Eigen::Vector2d uv;
  ASSERT_TRUE(cache.find("front_optical")->project(Eigen::Vector3d(0, 0, 1), &uv));
  EXPECT_NEAR(uv.x(), 500.0, 1e-9);  // the optical axis lands on the new centre
  EXPECT_NEAR(uv.y(), 272.0, 1e-9);
}

TEST(CameraInfo, ModelFittingAnImageNamesWhyNot) {
  const Rig rig = loadRig();
  CameraModelsByFrame cache;
  std::string why;
  EXPECT_EQ(cache.fitting(nullptr, 1024, 544, "/depth/camera_info", &why), nullptr);
  EXPECT_EQ(why, "no camera_info on /depth/camera_info");
  auto info = boost::make_shared<sensor_msgs::CameraInfo>(toCameraInfo(rig.cameras[0], ros::Time()));
  EXPECT_EQ(cache.fitting(info, 512, 272, "t", &why), nullptr);
  EXPECT_EQ(why, "camera_info 1024x544 does not fit the image (512x272)");
  const auto model = cache.fitting(info, 1024, 544, "t", &why);
  ASSERT_NE(model, nullptr);
  expectSameProjections(*model, rig.cameras[0].model);
  auto bad = boost::make_shared<sensor_msgs::CameraInfo>(*info);
  bad->D[0] = -0.5;
  EXPECT_EQ(cache.fitting(bad, 1024, 544, "t", &why), nullptr);
  EXPECT_EQ(why.rfind("camera_info refused: ", 0), 0u) << why;
  EXPECT_NE(why.find("D[0] (xi): must be >= 0, got -0.5"), std::string::npos) << why;
}

}  // namespace
}  // namespace fisheye_mapping
