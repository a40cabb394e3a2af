// Rig calibration: Kalibr camchain + mount loading (all models, a 5-camera
// chain composed by hand), the real V-Charge calib.txt, writing back, and a
// table of bad files with their specific errors.
#include <cstdio>
#include <fstream>
#include <functional>
#include <string>

#include <gtest/gtest.h>
#include <sys/stat.h>

#include "fisheye_mapping/core/camera/rig.h"
#include "test_utils.h"

namespace fisheye_mapping {
namespace {

// Five cameras, three models. The chain, by hand (positions in cam0's frame):
//   cam1 = T_c1_c0 translation (-0.3, 0, 0)            -> cam1 at (0.3, 0, 0)
//   cam2 = T_c2_c1 rotation R = Ry(+90 deg), no shift  -> at (0.3, 0, 0), its z
//          axis is R^T e_z = (-1, 0, 0) in cam1 (= cam0) coordinates
//   cam3 = T_c3_c2 translation (0, 0, -1): 1 m along cam2's z -> (-0.7, 0, 0)
//   cam4 = T_c4_c3 translation (0, 0.5, 0): 0.5 m along -y of cam3, whose y is
//          cam0's y                                      -> (-0.7, -0.5, 0)
// Mount: cam0 optical frame -> base_link: R = [[0,0,1],[-1,0,0],[0,-1,0]],
// t = (1.5, 0, 1.6), so cam4 sits at R (-0.7, -0.5, 0) + t = (1.5, 0.7, 2.1).
const char* kCamchain = R"YAML(
cam0:
  camera_model: omni
  intrinsics: [1.1, 300.0, 301.0, 512.0, 272.0]
  distortion_model: radtan
  distortion_coeffs: [-0.3, 0.08, 0.001, -0.0005]
  resolution: [1024, 544]
  rostopic: /cam0/image_raw
cam1:
  camera_model: ds
  intrinsics: [-0.2, 0.6, 350.0, 351.0, 511.5, 271.5]
  distortion_model: none
  distortion_coeffs: []
  resolution: [1024, 544]
  rostopic: /cam1/image_raw
  T_cn_cnm1:
  - [1.0, 0.0, 0.0, -0.3]
  - [0.0, 1.0, 0.0, 0.0]
  - [0.0, 0.0, 1.0, 0.0]
  - [0.0, 0.0, 0.0, 1.0]
cam2:
  camera_model: pinhole
  intrinsics: [330.0, 331.0, 511.5, 271.5]
  distortion_model: equidistant
  distortion_coeffs: [0.02, -0.005, 0.001, -0.0002]
  resolution: [1024, 544]
  rostopic: /cam2/image_raw
  T_cn_cnm1:
  - [0.0, 0.0, 1.0, 0.0]
  - [0.0, 1.0, 0.0, 0.0]
  - [-1.0, 0.0, 0.0, 0.0]
  - [0.0, 0.0, 0.0, 1.0]
cam3:
  camera_model: pinhole
  intrinsics: [400.0, 410.0, 320.0, 240.0]
  distortion_model: radtan
  distortion_coeffs: [-0.28, 0.07, 0.001, -0.0005]
  resolution: [640, 480]
  rostopic: /cam3/image_raw
  T_cn_cnm1:
  - [1.0, 0.0, 0.0, 0.0]
  - [0.0, 1.0, 0.0, 0.0]
  - [0.0, 0.0, 1.0, -1.0]
  - [0.0, 0.0, 0.0, 1.0]
cam4:
  camera_model: omni
  intrinsics: [0.9, 290.0, 290.0, 512.0, 272.0]
  distortion_model: none
  distortion_coeffs: []
  resolution: [1024, 544]
  rostopic: /cam4/image_raw
  T_cn_cnm1:
  - [1.0, 0.0, 0.0, 0.0]
  - [0.0, 1.0, 0.0, 0.5]
  - [0.0, 0.0, 1.0, 0.0]
  - [0.0, 0.0, 0.0, 1.0]
)YAML";

const char* kMount = R"YAML(
base_frame: base_link
T_base_cam0:
  - [0.0, 0.0, 1.0, 1.5]
  - [-1.0, 0.0, 0.0, 0.0]
  - [0.0, -1.0, 0.0, 1.6]
  - [0.0, 0.0, 0.0, 1.0]
frame_ids: {cam0: front_center_optical, cam4: side_optical}
)YAML";

class RigCalibration : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/fm_rig_test_XXXXXX";
    dir_ = mkdtemp(tmpl);
  }
  void TearDown() override { std::system(("rm -rf " + dir_).c_str()); }

  std::string write(const std::string& name, const std::string& text) {
    const std::string path = dir_ + "/" + name;
    std::ofstream(path) << text;
    return path;
  }
  std::string dir_;
};

void expectVec(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double tol = 1e-12) {
  EXPECT_LT((a - b).norm(), tol) << a.transpose() << " vs " << b.transpose();
}

TEST_F(RigCalibration, LoadsAFiveCameraKalibrChain) {
  const Rig rig = loadKalibrRig(write("camchain.yaml", kCamchain), write("mount.yaml", kMount));
  ASSERT_EQ(rig.cameras.size(), 5u);
  EXPECT_EQ(rig.base_frame, "base_link");

  const auto& p0 = rig.cameras[0].model.params();
  EXPECT_EQ(rig.cameras[0].model.type(), CameraModelType::kUnified);
  EXPECT_DOUBLE_EQ(p0.xi, 1.1);
  EXPECT_DOUBLE_EQ(p0.fx, 300.0);
  EXPECT_DOUBLE_EQ(p0.fy, 301.0);
  EXPECT_DOUBLE_EQ(p0.k1, -0.3);
  EXPECT_DOUBLE_EQ(p0.p2, -0.0005);
  EXPECT_EQ(rig.cameras[1].model.type(), CameraModelType::kDoubleSphere);
  EXPECT_DOUBLE_EQ(rig.cameras[1].model.params().alpha, 0.6);
  EXPECT_DOUBLE_EQ(rig.cameras[1].model.params().xi, -0.2);
  EXPECT_EQ(rig.cameras[2].model.type(), CameraModelType::kKannalaBrandt);
  EXPECT_DOUBLE_EQ(rig.cameras[2].model.params().k4, -0.0002);
  EXPECT_EQ(rig.cameras[3].model.type(), CameraModelType::kPinhole);
  EXPECT_EQ(rig.cameras[3].model.width(), 640);
  EXPECT_EQ(rig.cameras[4].model.type(), CameraModelType::kUnified);
  EXPECT_DOUBLE_EQ(rig.cameras[4].model.params().k1, 0.0);

  EXPECT_EQ(rig.cameras[2].rostopic, "/cam2/image_raw");
  EXPECT_EQ(rig.cameras[0].frame_id, "front_center_optical");
  EXPECT_EQ(rig.cameras[1].frame_id, "cam1");
  EXPECT_EQ(rig.cameras[4].frame_id, "side_optical");

  // Positions in cam0, composed by hand in the comment above.
  expectVec(rig.cameras[0].T_cam0_cam.translation(), {0, 0, 0});
  expectVec(rig.cameras[1].T_cam0_cam.translation(), {0.3, 0, 0});
  expectVec(rig.cameras[2].T_cam0_cam.translation(), {0.3, 0, 0});
  expectVec(rig.cameras[3].T_cam0_cam.translation(), {-0.7, 0, 0});
  expectVec(rig.cameras[4].T_cam0_cam.translation(), {-0.7, -0.5, 0});
  // cam2..4 look along cam0's -x, which is base_link's +y (left).
  expectVec(rig.cameras[2].T_cam0_cam.linear().col(2), {-1, 0, 0});
  expectVec(rig.cameras[4].T_base_cam.linear().col(2), {0, 1, 0});
  // In base_link.
  expectVec(rig.cameras[0].T_base_cam.translation(), {1.5, 0, 1.6});
  expectVec(rig.cameras[4].T_base_cam.translation(), {1.5, 0.7, 2.1});
  // cam0 looks forward (+x of base_link), its image down is base_link's -z.
  expectVec(rig.cameras[0].T_base_cam.linear().col(2), {1, 0, 0});
  expectVec(rig.cameras[0].T_base_cam.linear().col(1), {0, 0, -1});

  EXPECT_EQ(rig.indexOf("cam3"), 3);
  EXPECT_EQ(rig.indexOf("cam9"), -1);
  EXPECT_THROW(rig.camera("cam9"), CalibrationError);
}

TEST_F(RigCalibration, WriteThenLoadGivesTheSameRig) {
  const Rig rig = loadKalibrRig(write("camchain.yaml", kCamchain), write("mount.yaml", kMount));
  const std::string chain2 = dir_ + "/out_camchain.yaml", mount2 = dir_ + "/out_mount.yaml";
  writeKalibrRig(rig, chain2, mount2);
  const Rig back = loadKalibrRig(chain2, mount2);
  ASSERT_EQ(back.cameras.size(), rig.cameras.size());
  for (size_t i = 0; i < rig.cameras.size(); ++i) {
    const auto& a = rig.cameras[i];
    const auto& b = back.cameras[i];
    EXPECT_EQ(a.model.name(), b.model.name());
    EXPECT_EQ(a.frame_id, b.frame_id);
    EXPECT_EQ(a.rostopic, b.rostopic);
    EXPECT_EQ(0, std::memcmp(&a.model.params(), &b.model.params(), sizeof(FmCameraT<double>)))
        << a.name;
    EXPECT_LT((a.T_base_cam.matrix() - b.T_base_cam.matrix()).cwiseAbs().maxCoeff(), 1e-12);
  }
}

TEST_F(RigCalibration, DefaultRigMatchesItsDescription) {
  // config/rig: five cameras on a lateral bar 1.65 m above the ground, 1.2 m
  // ahead of base_link, at y = 0, +0.3, -0.3, +0.6, -0.6, yawed 0, +10, -10,
  // +20, -20 deg and pitched 5 deg down.
  const std::string dir = FM_TEST_DATA_DIR "/../../config/rig/";
  const Rig rig = loadKalibrRig(dir + "default_camchain.yaml", dir + "default_mount.yaml");
  ASSERT_EQ(rig.cameras.size(), 5u);
  const double ys[] = {0.0, 0.3, -0.3, 0.6, -0.6};
  const double yaws[] = {0.0, 10.0, -10.0, 20.0, -20.0};
  for (int i = 0; i < 5; ++i) {
    const auto& cam = rig.cameras[i];
    expectVec(cam.T_base_cam.translation(), {1.2, ys[i], 1.65}, 1e-9);
    const Eigen::Vector3d axis = cam.T_base_cam.linear().col(2);
    EXPECT_NEAR(std::atan2(axis.y(), axis.x()) * 180 / M_PI, yaws[i], 1e-7) << cam.name;
    EXPECT_NEAR(std::asin(axis.z()) * 180 / M_PI, -5.0, 1e-7) << cam.name;
    EXPECT_EQ(cam.model.width(), 1024);
    EXPECT_EQ(cam.model.height(), 544);
    EXPECT_EQ(cam.frame_id, cam.name + "_optical_frame");
  }
  // Baselines from 0.3 m to 1.2 m.
  EXPECT_NEAR((rig.cameras[3].T_cam0_cam.translation() - rig.cameras[4].T_cam0_cam.translation()).norm(),
              1.2, 1e-9);
}

TEST_F(RigCalibration, LoadsTheRealVChargeCalibration) {
  const std::string path =
      test::sharedDir(FM_SHARED_DIR) + "/data/vcharge_fisheye/left/calib.txt";
  if (!std::ifstream(path)) GTEST_SKIP() << "no V-Charge data at " << path;
  // The images are 1280x800 (../shared/data/vcharge_fisheye/README.md).
  const Rig rig = loadPslCalibration(path, 1280, 800, "left");
  ASSERT_EQ(rig.cameras.size(), 1u);
  const auto& cam = rig.cameras[0];
  const auto& p = cam.model.params();
  // Numbers as printed in the file.
  EXPECT_EQ(cam.model.type(), CameraModelType::kUnified);
  EXPECT_NEAR(p.fx, 895.54818314068166, 1e-9);
  EXPECT_NEAR(p.cx, 649.62356964542516, 1e-9);
  EXPECT_NEAR(p.fy, 894.74426130897348, 1e-9);
  EXPECT_NEAR(p.cy, 398.71903485692013, 1e-9);
  EXPECT_NEAR(p.xi, 1.1584422115726898, 1e-12);
  EXPECT_NEAR(p.k1, -0.33084335078197569, 1e-12);
  EXPECT_NEAR(p.p2, -3.6412961593787842e-05, 1e-15);
  expectVec(cam.T_base_cam.translation(), {1.9070741295, 1.3975064583, 0.0673496602}, 1e-9);
  // The left camera looks to the left of the car (+y of the system) and down.
  const Eigen::Vector3d axis = cam.T_base_cam.linear().col(2);
  EXPECT_NEAR(axis.y(), 0.7440161452, 1e-6);
  EXPECT_NEAR(axis.z(), -0.6641483201, 1e-6);
  // xi > 1: the valid cone is acos(-1/xi) = 149.7 deg (no radtan fold here).
  EXPECT_NEAR(cam.model.maxValidAngle(), std::acos(-1.0 / p.xi), 1e-6);
  // The principal point is the optical axis.
  Eigen::Vector3d ray;
  ASSERT_TRUE(cam.model.unproject({p.cx, p.cy}, &ray));
  expectVec(ray, {0, 0, 1}, 1e-12);
  EXPECT_NO_THROW(checkImageSize(cam, 1280, 800));
}

TEST_F(RigCalibration, ImageSizeMismatchNamesBothSizes) {
  const Rig rig = loadKalibrRig(write("camchain.yaml", kCamchain), write("mount.yaml", kMount));
  try {
    checkImageSize(rig.cameras[3], 1024, 544);
    FAIL();
  } catch (const CalibrationError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("cam3.resolution"), std::string::npos) << msg;
    EXPECT_NE(msg.find("1024x544"), std::string::npos) << msg;
    EXPECT_NE(msg.find("640x480"), std::string::npos) << msg;
  }
}

struct BadCase {
  const char* what;
  const char* find;     // text of the good camchain to change ("" = use mount)
  const char* replace;  // its replacement
  const char* mount_find;
  const char* mount_replace;
  const char* expected;  // substring of the error message
};

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  if (from.empty()) return text;
  const size_t at = text.find(from);
  if (at == std::string::npos) throw std::logic_error("test setup: '" + from + "' not found");
  return text.replace(at, from.size(), to);
}

TEST_F(RigCalibration, BadFilesGiveSpecificErrors) {
  const BadCase cases[] = {
      {"missing field", "  intrinsics: [330.0, 331.0, 511.5, 271.5]\n", "", "", "",
       "camchain.yaml: cam2.intrinsics: missing"},
      {"misspelled field", "  camera_model: omni\n  intrinsics: [1.1", "  camera_modle: omni\n  intrinsics: [1.1",
       "", "", "camchain.yaml: cam0.camera_model: missing"},
      {"wrong count", "[1.1, 300.0, 301.0, 512.0, 272.0]", "[1.1, 300.0, 301.0, 512.0]", "", "",
       "cam0.intrinsics: expected 5 values for camera_model 'omni', got 4"},
      {"mistyped value", "[1.1, 300.0, 301.0", "[1.1, three, 301.0", "", "",
       "cam0.intrinsics[1]: expected a number, got 'three'"},
      {"non-positive focal length", "[1.1, 300.0, 301.0", "[1.1, -300.0, 301.0", "", "",
       "cam0.intrinsics: fx must be positive"},
      {"negative xi", "[1.1, 300.0", "[-0.1, 300.0", "", "", "cam0.intrinsics: xi must be >= 0"},
      {"alpha out of range", "[-0.2, 0.6,", "[-0.2, 1.6,", "", "",
       "cam1.intrinsics: alpha must lie in [0, 1], got 1.6"},
      {"unknown model", "camera_model: omni", "camera_model: fisheye", "", "",
       "cam0.camera_model: unknown camera model 'fisheye'"},
      {"unknown distortion", "distortion_model: radtan\n  distortion_coeffs: [-0.28",
       "distortion_model: fov\n  distortion_coeffs: [-0.28", "", "",
       "cam3.distortion_model: unknown distortion model 'fov'"},
      {"distortion count", "[-0.28, 0.07, 0.001, -0.0005]", "[-0.28, 0.07, 0.001]", "", "",
       "cam3.distortion_coeffs: expected 4 values"},
      {"unsupported combination", "distortion_model: none\n  distortion_coeffs: []\n  resolution: [1024, 544]\n  rostopic: /cam1",
       "distortion_model: radtan\n  distortion_coeffs: [0, 0, 0, 0]\n  resolution: [1024, 544]\n  rostopic: /cam1",
       "", "", "cam1.distortion_model: ds supports only 'none'"},
      {"resolution count", "resolution: [640, 480]", "resolution: [640, 480, 3]", "", "",
       "cam3.resolution: expected 2 values"},
      {"zero resolution", "resolution: [640, 480]", "resolution: [640, 0]", "", "",
       "cam3.resolution: resolution must be positive"},
      {"non-orthonormal rotation", "  - [0.0, 0.0, 1.0, 0.0]\n  - [0.0, 1.0, 0.0, 0.0]\n  - [-1.0",
       "  - [0.0, 0.0, 1.0, 0.0]\n  - [0.0, 1.1, 0.0, 0.0]\n  - [-1.0", "", "",
       "cam2.T_cn_cnm1: rotation is not orthonormal"},
      {"reflection", "  - [1.0, 0.0, 0.0, -0.3]", "  - [-1.0, 0.0, 0.0, -0.3]", "", "",
       "cam1.T_cn_cnm1: rotation has determinant -1"},
      {"missing chain transform", "  T_cn_cnm1:\n  - [1.0, 0.0, 0.0, -0.3]\n  - [0.0, 1.0, 0.0, 0.0]\n  - [0.0, 0.0, 1.0, 0.0]\n  - [0.0, 0.0, 0.0, 1.0]\n",
       "", "", "", "cam1.T_cn_cnm1: missing"},
      {"matrix row count", "  - [0.0, 1.0, 0.0, 0.5]", "  - [0.0, 1.0, 0.0]", "", "",
       "cam4.T_cn_cnm1[1]: expected 4 values in a matrix row, got 3"},
      {"gap in the cameras", "cam2:", "cam7:", "", "", "camchain.yaml: cam2: missing"},
      {"yaml syntax", "cam1:\n", "cam1: [\n", "", "", "camchain.yaml: YAML syntax error"},
      {"mount without T_base_cam0", "", "", "T_base_cam0:", "T_base_camera0:",
       "mount.yaml: T_base_cam0: missing"},
      {"mount non-rigid", "", "", "- [0.0, 0.0, 1.0, 1.5]", "- [0.0, 0.0, 2.0, 1.5]",
       "mount.yaml: T_base_cam0: rotation is not orthonormal"},
      {"mount last row", "", "", "- [0.0, 0.0, 0.0, 1.0]", "- [0.0, 0.0, 0.5, 1.0]",
       "mount.yaml: T_base_cam0: last row must be [0, 0, 0, 1]"},
      {"frame id of an unknown camera", "", "", "cam4: side_optical", "cam9: side_optical",
       "mount.yaml: frame_ids.cam9: no such camera"},
      // Hostile files (issue 15): each is refused with the file and the field.
      {"camera key beyond int range", "cam2:", "cam2147483648:", "", "",
       "camchain.yaml: cam2147483648: camera index out of range: a rig has at most 64 cameras (cam0 ... cam63)"},
      {"camera key beyond the rig limit", "cam2:", "cam64:", "", "",
       "camchain.yaml: cam64: camera index out of range"},
      {"camera key with a leading zero", "cam1:\n", "cam01:\n", "", "",
       "camchain.yaml: cam01: camera keys are cam0, cam1, ... without leading zeros"},
      {"list as a key", "cam1:\n", "? [a, b]\n: 1\ncam1:\n", "", "",
       "camchain.yaml: (top level): keys must be plain names, got a list"},
      {"absurd focal length", "[400.0, 410.0, 320.0, 240.0]", "[1e300, 410.0, 320.0, 240.0]", "", "",
       "camchain.yaml: cam3.intrinsics: fx must lie in (0, 1e+06] pixels, got 1e+300"},
      {"absurd principal point", "[400.0, 410.0, 320.0, 240.0]", "[400.0, 410.0, 320.0, 1e12]", "", "",
       "camchain.yaml: cam3.intrinsics: cy must lie in [-1e+06, 1e+06], got 1e+12"},
      {"absurd distortion", "[-0.28, 0.07, 0.001, -0.0005]", "[-0.28, 1e9, 0.001, -0.0005]", "", "",
       "camchain.yaml: cam3.distortion_coeffs: k2 must lie in [-1000, 1000], got 1e+09"},
      {"absurd xi", "[0.9, 290.0", "[1e9, 290.0", "", "", "camchain.yaml: cam4.intrinsics: xi must be at most 1000"},
      {"huge resolution", "resolution: [640, 480]", "resolution: [100000, 100000]", "", "",
       "camchain.yaml: cam3.resolution: resolution must be at most 20000x20000 pixels, got 100000x100000"},
      {"resolution beyond int range", "resolution: [640, 480]", "resolution: [1e300, 480]", "", "",
       "camchain.yaml: cam3.resolution: resolution must be at most 20000x20000 pixels, got 1e+300x480"},
      {"absurd translation", "  - [0.0, 1.0, 0.0, 0.5]", "  - [0.0, 1.0, 0.0, 1e300]", "", "",
       "camchain.yaml: cam4.T_cn_cnm1: translation must lie within 10000 m"},
      {"two cameras, one frame", "", "", "cam4: side_optical", "cam4: front_center_optical",
       "mount.yaml: frame_ids.cam4: frame 'front_center_optical' is also cam0's; each camera needs its own tf frame"},
      {"frame id clashing with a default", "", "", "cam0: front_center_optical", "cam0: cam2",
       "mount.yaml: (frame of cam2): frame 'cam2' is also cam0's"},
      {"camera frame is the base frame", "", "", "cam4: side_optical", "cam4: base_link",
       "mount.yaml: frame_ids.cam4: frame 'base_link' is the base frame; each camera needs its own frame"},
      {"empty frame id", "", "", "cam4: side_optical", "cam4: ''", "mount.yaml: frame_ids.cam4: must not be empty"},
      {"frame id not a string", "", "", "cam4: side_optical", "cam4: [a, b]",
       "mount.yaml: frame_ids.cam4: expected a string"},
  };
  for (const BadCase& c : cases) {
    SCOPED_TRACE(c.what);
    const std::string chain = write("camchain.yaml", replaced(kCamchain, c.find, c.replace));
    const std::string mount = write("mount.yaml", replaced(kMount, c.mount_find, c.mount_replace));
    try {
      loadKalibrRig(chain, mount);
      ADD_FAILURE() << "loaded a bad file";
    } catch (const CalibrationError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(c.expected), std::string::npos) << "message: " << msg;
      EXPECT_NE(msg.find(dir_), std::string::npos) << "no file path in: " << msg;
    }
  }
}

TEST_F(RigCalibration, DirectoriesHugeFilesAndStringsAreCalibrationErrors) {
  const std::string mount = write("mount.yaml", kMount);
  const auto error = [](const std::function<void()>& f) -> std::string {
    try {
      f();
    } catch (const CalibrationError& e) {
      return e.what();
    }
    return "(loaded)";
  };
  EXPECT_EQ(error([&] { loadKalibrRig(dir_, mount); }), dir_ + ": is a directory, expected a calibration file");
  EXPECT_EQ(error([&] { loadKalibrRig(write("camchain.yaml", kCamchain), dir_); }),
            dir_ + ": is a directory, expected a calibration file");
  EXPECT_EQ(error([&] { loadPslCalibration(dir_, 1280, 800); }), dir_ + ": is a directory, expected a calibration file");
  const std::string big = write("big.yaml", "# " + std::string(2 << 20, 'x') + "\n");
  EXPECT_EQ(error([&] { loadKalibrRig(big, mount); }),
            big + ": too large for a calibration file (more than 1048576 bytes)");
  // The string entry point names the files it is given.
  EXPECT_EQ(loadKalibrRigFromStrings(kCamchain, kMount).cameras.size(), 5u);
  EXPECT_EQ(error([&] { loadKalibrRigFromStrings("cam0: [", kMount, "a.yaml", "b.yaml"); }).rfind("a.yaml: YAML syntax error", 0),
            0u);
  // A camera key given twice.
  const std::string twice = std::string(kCamchain) + "cam3:\n  camera_model: pinhole\n";
  const std::string msg = error([&] { loadKalibrRigFromStrings(twice, kMount); });
  EXPECT_TRUE(msg == "camchain.yaml: cam3: appears twice" || msg.rfind("camchain.yaml: YAML syntax error", 0) == 0) << msg;
}

TEST_F(RigCalibration, MissingFilesAndBadPslFiles) {
  try {
    loadKalibrRig(dir_ + "/nope.yaml", write("mount.yaml", kMount));
    FAIL();
  } catch (const CalibrationError& e) {
    EXPECT_NE(std::string(e.what()).find("nope.yaml: cannot open file"), std::string::npos) << e.what();
  }
  const char* good_psl =
      "895.5 0 649.6 894.7 398.7 1.158 -0.33 0.086 -0.0006 -0.00003\n\n"
      "1 0 0 1.9\n0 1 0 1.4\n0 0 1 0.06\n";
  EXPECT_NO_THROW(loadPslCalibration(write("calib.txt", good_psl), 1280, 800));
  struct {
    const char* text;
    const char* expected;
  } cases[] = {
      {"895.5 0 649.6 894.7 398.7 1.158 -0.33 0.086 -0.0006\n1 0 0 1.9\n0 1 0 1.4\n0 0 1 0.06\n",
       "expected 10 values, got 9"},
      {"895.5 0 649.6 894.7 398.7 1.158 -0.33 0.086 -0.0006 -0.00003\n1 0 0 1.9\n0 1 0 1.4\n",
       "expected 4 non-empty lines"},
      {"895.5 0 649.6 894.7 398.7 1.158 -0.33 0.086 -0.0006 x\n1 0 0 1.9\n0 1 0 1.4\n0 0 1 0\n",
       "line 1: not a number: 'x'"},
      {"-895.5 0 649.6 894.7 398.7 1.158 -0.33 0.086 -0.0006 0\n1 0 0 1.9\n0 1 0 1.4\n0 0 1 0\n",
       "intrinsics: fx must be positive"},
      {"895.5 0 649.6 894.7 398.7 1.158 -0.33 0.086 -0.0006 0\n1 0 0 1.9\n0 2 0 1.4\n0 0 1 0\n",
       "[R | C]: rotation is not orthonormal"},
      {"895.5 0 649.6 894.7 398.7 1.158 -0.33 0.086 -0.0006 nan\n1 0 0 1.9\n0 1 0 1.4\n0 0 1 0\n",
       "calib.txt: line 1: not a number: 'nan'"},
      {"1e300 0 649.6 894.7 398.7 1.158 -0.33 0.086 -0.0006 0\n1 0 0 1.9\n0 1 0 1.4\n0 0 1 0\n",
       "calib.txt: intrinsics: fx must lie in (0, 1e+06] pixels, got 1e+300"},
      {"895.5 0 649.6 894.7 398.7 1.158 -0.33 0.086 -0.0006 0\n1 0 0 1.9\n0 1 0 1.4\n0 0 1 0\n1 2 3\n",
       "calib.txt: line 5: expected 4 non-empty lines (intrinsics, then a 3x4 [R | C]), got more"},
      {"895.5 0 649.6 894.7 398.7 1.158 -0.33 0.086 -0.0006 0 1\n1 0 0 1.9\n0 1 0 1.4\n0 0 1 0\n",
       "calib.txt: line 1: too many values (at most 10 on a line)"},
  };
  for (const auto& c : cases) {
    try {
      loadPslCalibration(write("calib.txt", c.text), 1280, 800);
      ADD_FAILURE() << "loaded: " << c.text;
    } catch (const CalibrationError& e) {
      EXPECT_NE(std::string(e.what()).find(c.expected), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("calib.txt"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace fisheye_mapping
