// Rig refinement against the synthetic world's exact geometry: frame sets of
// the urban world rendered with the true default rig; the refinement is given
// the rig with its support cameras' rotations perturbed by known amounts and
// must recover the truth. Also: an exact rig stays as it is, featureless
// images and self-masks leave too few matches (no change), input errors, and
// the refine_rig tool on a make_drive bag.
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>
#include <rosbag/bag.h>
#include <sensor_msgs/Image.h>

#include "fisheye_mapping/core/camera/rig_refinement.h"
#include "fisheye_mapping/core/sim/synthetic_world.h"

namespace fm = fisheye_mapping;

namespace {

using Clock = std::chrono::steady_clock;
double secSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

const std::string kConfig = FM_CONFIG_DIR;
const std::string kCamchain = kConfig + "/rig/default_camchain.yaml";
const std::string kMount = kConfig + "/rig/default_mount.yaml";
constexpr double kDeg = M_PI / 180.0;
constexpr double kToleranceDeg = 0.05;

double angleDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle() / kDeg;
}

// Rotation of camera c relative to camera ref.
Eigen::Matrix3d relRotation(const fm::Rig& rig, int ref, int c) {
  return (rig.cameras[ref].T_base_cam.inverse() * rig.cameras[c].T_base_cam).linear();
}

// Camera c rotated about its own centre by `deg` about `axis` (camera frame).
fm::Rig perturbed(const fm::Rig& rig, int ref, int c, const Eigen::Vector3d& axis, double deg) {
  Eigen::Isometry3d T = rig.cameras[ref].T_base_cam.inverse() * rig.cameras[c].T_base_cam;
  T.linear() = T.linear() * Eigen::AngleAxisd(deg * kDeg, axis.normalized()).toRotationMatrix();
  return fm::withRelativePose(rig, ref, c, T);
}

// Every camera's T_base_cam = T_base_cam0 * T_cam0_cam, cam0's T_cam0_cam = I.
void expectConsistent(const fm::Rig& rig) {
  EXPECT_TRUE(rig.cameras[0].T_cam0_cam.isApprox(Eigen::Isometry3d::Identity(), 1e-12));
  for (const auto& c : rig.cameras)
    EXPECT_TRUE((rig.cameras[0].T_base_cam * c.T_cam0_cam).isApprox(c.T_base_cam, 1e-9)) << c.name;
}

void printResult(const fm::RigRefinementResult& r, const fm::Rig& truth, int ref) {
  for (const auto& c : r.cameras) {
    if (c.camera == ref) continue;
    std::printf("  %s %-15s matches %5d candidates %5d inliers %5d  rms %.4f -> %.4f deg  correction %.3f deg  "
                "error vs truth %.4f deg\n",
                c.name.c_str(), fm::toString(c.status), c.matches, c.candidates, c.inliers, c.rms_before_deg,
                c.rms_after_deg, c.correction_deg,
                angleDeg(relRotation(truth, ref, c.camera), relRotation(r.rig, ref, c.camera)));
  }
}

std::string run(const std::string& cmd, int* rc) {
  std::string out;
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  char buf[512];
  while (fgets(buf, sizeof(buf), p)) out += buf;
  const int status = pclose(p);
  *rc = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return out;
}

bool exists(const std::string& path) { return std::ifstream(path).good(); }

class RigRefinementTest : public ::testing::Test {
 protected:
  // Four frame sets 16 m apart along the urban route, rendered once.
  static void SetUpTestSuite() {
    const auto t0 = Clock::now();
    rig_ = new fm::Rig(fm::loadKalibrRig(kCamchain, kMount));
    fm::synth::WorldConfig wc;
    wc.route_length = 200;
    const fm::synth::World world(wc);
    sets_ = new std::vector<std::vector<cv::Mat>>;
    std::vector<std::vector<Eigen::Vector3f>> rays;
    for (const auto& cam : rig_->cameras) rays.push_back(fm::pixelRays(cam.model));
    for (int k = 0; k < 4; ++k) {
      const double t = 2.0 * k;
      std::vector<cv::Mat> set;
      for (size_t c = 0; c < rig_->cameras.size(); ++c) {
        const auto& cam = rig_->cameras[c];
        set.push_back(world.render(cam.model, rays[c], world.egoPose(t) * cam.T_base_cam, t, 64 * k + c).image);
      }
      sets_->push_back(set);
    }
    std::printf("rendered %zu frame sets of %zu cameras in %.1f s\n", sets_->size(), rig_->cameras.size(),
                secSince(t0));
  }
  static void TearDownTestSuite() {
    delete rig_;
    delete sets_;
  }
  static fm::Rig* rig_;
  static std::vector<std::vector<cv::Mat>>* sets_;
};
fm::Rig* RigRefinementTest::rig_ = nullptr;
std::vector<std::vector<cv::Mat>>* RigRefinementTest::sets_ = nullptr;

const std::vector<Eigen::Vector3d> kAxes = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                            Eigen::Vector3d::UnitZ(), Eigen::Vector3d(1, -1, 1)};

TEST_F(RigRefinementTest, RecoversRotationsPerturbedByHalfADegree) {
  fm::Rig bad = *rig_;
  for (int c = 1; c < 5; ++c) bad = perturbed(bad, 0, c, kAxes[c - 1], 0.5);
  const cv::Mat before = (*sets_)[1][2].clone();
  const auto t0 = Clock::now();
  const fm::RigRefinementResult r = fm::refineRig(bad, 0, *sets_);
  EXPECT_EQ(cv::norm(before, (*sets_)[1][2], cv::NORM_INF), 0.0) << "the input images were modified";
  std::printf("refined in %.1f s\n", secSince(t0));
  printResult(r, *rig_, 0);
  EXPECT_EQ(r.applied(), 4);
  EXPECT_EQ(r.cameras[0].status, fm::CameraRefinement::Status::kReference);
  for (int c = 1; c < 5; ++c) {
    const auto& cr = r.cameras[c];
    SCOPED_TRACE(cr.name);
    EXPECT_NEAR(angleDeg(relRotation(*rig_, 0, c), relRotation(bad, 0, c)), 0.5, 1e-9);
    EXPECT_LT(angleDeg(relRotation(*rig_, 0, c), relRotation(r.rig, 0, c)), kToleranceDeg);
    EXPECT_EQ(cr.status, fm::CameraRefinement::Status::kApplied);
    EXPECT_GT(cr.inliers, 1000);
    EXPECT_LT(cr.rms_after_deg, cr.rms_before_deg);
    EXPECT_NEAR(cr.correction_deg, 0.5, kToleranceDeg);
    // Rotated about its own centre: the position is kept.
    EXPECT_LT((r.rig.cameras[c].T_cam0_cam.translation() - rig_->cameras[c].T_cam0_cam.translation()).norm(), 1e-9);
  }
  EXPECT_TRUE(r.rig.cameras[0].T_base_cam.isApprox(rig_->cameras[0].T_base_cam, 1e-12));
  expectConsistent(r.rig);
}

TEST_F(RigRefinementTest, LeavesAnExactRigAsItIs) {
  const fm::RigRefinementResult r = fm::refineRig(*rig_, 0, *sets_);
  printResult(r, *rig_, 0);
  for (int c = 1; c < 5; ++c) {
    SCOPED_TRACE(r.cameras[c].name);
    EXPECT_NE(r.cameras[c].status, fm::CameraRefinement::Status::kTooFewInliers);
    EXPECT_LT(angleDeg(relRotation(*rig_, 0, c), relRotation(r.rig, 0, c)), kToleranceDeg);
    EXPECT_LT(r.cameras[c].correction_deg, kToleranceDeg);
  }
}

// Another reference camera: cam0 itself is corrected, and the rig's cam0-based
// extrinsics and mount follow.
TEST_F(RigRefinementTest, RefinesCam0AgainstAnotherReference) {
  fm::Rig bad = perturbed(*rig_, 1, 0, Eigen::Vector3d(0, 1, 1), 0.4);
  bad = perturbed(bad, 1, 2, Eigen::Vector3d(1, 0, -1), 0.4);
  const fm::RigRefinementResult r = fm::refineRig(bad, 1, *sets_);
  printResult(r, *rig_, 1);
  for (int c : {0, 2, 3, 4}) {
    SCOPED_TRACE(r.cameras[c].name);
    EXPECT_LT(angleDeg(relRotation(*rig_, 1, c), relRotation(r.rig, 1, c)), kToleranceDeg);
  }
  EXPECT_EQ(r.cameras[0].status, fm::CameraRefinement::Status::kApplied);
  EXPECT_TRUE(r.rig.cameras[1].T_base_cam.isApprox(bad.cameras[1].T_base_cam, 1e-12));
  expectConsistent(r.rig);
}

TEST_F(RigRefinementTest, TranslationDirectionOptionKeepsBaselineLength) {
  fm::Rig bad = *rig_;
  for (int c = 1; c < 5; ++c) bad = perturbed(bad, 0, c, kAxes[c - 1], 0.5);
  fm::RigRefinementConfig cfg;
  cfg.refine_translation = true;
  const fm::RigRefinementResult r = fm::refineRig(bad, 0, *sets_, {}, cfg);
  printResult(r, *rig_, 0);
  for (int c = 1; c < 5; ++c) {
    SCOPED_TRACE(r.cameras[c].name);
    const Eigen::Vector3d t_true = rig_->cameras[c].T_cam0_cam.translation();
    const Eigen::Vector3d t_new = r.rig.cameras[c].T_cam0_cam.translation();
    std::printf("  %s translation direction error %.3f deg\n", r.cameras[c].name.c_str(),
                std::acos(std::min(1.0, t_true.normalized().dot(t_new.normalized()))) / kDeg);
    EXPECT_NEAR(t_new.norm(), t_true.norm(), 1e-9);
    EXPECT_LT(angleDeg(relRotation(*rig_, 0, c), relRotation(r.rig, 0, c)), kToleranceDeg);
    EXPECT_LT(std::acos(std::min(1.0, t_true.normalized().dot(t_new.normalized()))) / kDeg, 1.0);
  }
}

TEST_F(RigRefinementTest, FeaturelessImagesGiveTooFewMatchesAndNoChange) {
  fm::Rig bad = perturbed(*rig_, 0, 1, Eigen::Vector3d::UnitX(), 0.5);
  for (int value : {0, 128}) {
    std::vector<std::vector<cv::Mat>> sets(3);
    for (auto& s : sets)
      for (const auto& cam : rig_->cameras)
        s.push_back(cv::Mat(cam.model.height(), cam.model.width(), CV_8UC1, cv::Scalar(value)));
    const fm::RigRefinementResult r = fm::refineRig(bad, 0, sets);
    EXPECT_EQ(r.applied(), 0);
    for (int c = 1; c < 5; ++c) {
      EXPECT_EQ(r.cameras[c].status, fm::CameraRefinement::Status::kTooFewInliers) << r.cameras[c].name;
      EXPECT_EQ(r.cameras[c].inliers, 0);
      EXPECT_TRUE(r.rig.cameras[c].T_base_cam.isApprox(bad.cameras[c].T_base_cam, 0.0));
      EXPECT_TRUE(r.rig.cameras[c].T_cam0_cam.isApprox(bad.cameras[c].T_cam0_cam, 0.0));
    }
  }
}

TEST_F(RigRefinementTest, SelfMasksRemoveFeatures) {
  fm::Rig bad = perturbed(*rig_, 0, 3, Eigen::Vector3d::UnitY(), 0.5);
  // The whole image is car body: no feature, no change.
  std::vector<cv::Mat> all;
  for (const auto& cam : rig_->cameras) all.emplace_back(cam.model.height(), cam.model.width(), CV_8UC1, cv::Scalar(255));
  const fm::RigRefinementResult none = fm::refineRig(bad, 0, *sets_, all);
  EXPECT_EQ(none.applied(), 0);
  for (int c = 1; c < 5; ++c) {
    EXPECT_EQ(none.cameras[c].status, fm::CameraRefinement::Status::kTooFewInliers);
    EXPECT_EQ(none.cameras[c].matches, 0);
  }
  EXPECT_TRUE(none.rig.cameras[3].T_base_cam.isApprox(bad.cameras[3].T_base_cam, 0.0));
  // Only the reference camera masked: nothing to match either.
  std::vector<cv::Mat> ref_only(5);
  ref_only[0] = all[0];
  EXPECT_EQ(fm::refineRig(bad, 0, *sets_, ref_only).applied(), 0);
  // The lower 40 % masked (a bonnet): fewer matches, the rotation still recovered.
  std::vector<cv::Mat> bonnet;
  for (const auto& cam : rig_->cameras) {
    cv::Mat m = cv::Mat::zeros(cam.model.height(), cam.model.width(), CV_8UC1);
    m.rowRange(int(0.6 * m.rows), m.rows).setTo(255);
    bonnet.push_back(m);
  }
  const fm::RigRefinementResult part = fm::refineRig(bad, 0, *sets_, bonnet);
  printResult(part, *rig_, 0);
  EXPECT_EQ(part.cameras[3].status, fm::CameraRefinement::Status::kApplied);
  EXPECT_LT(angleDeg(relRotation(*rig_, 0, 3), relRotation(part.rig, 0, 3)), kToleranceDeg);
}

TEST_F(RigRefinementTest, InputErrorsNameTheProblem) {
  const auto expectError = [&](const std::function<void()>& f, const std::string& part) {
    try {
      f();
      ADD_FAILURE() << "no error, expected one mentioning '" << part << "'";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
  };
  const std::vector<std::vector<cv::Mat>> one = {sets_->front()};
  expectError([&] { fm::refineRig(*rig_, 0, {}); }, "no frame set");
  expectError([&] { fm::refineRig(*rig_, 5, one); }, "reference");
  expectError([&] { fm::refineRig(*rig_, 0, {{one[0][0], one[0][1]}}); }, "has 2 images, the rig has 5");
  auto bad_size = one;
  cv::resize(bad_size[0][2], bad_size[0][2], cv::Size(512, 272));
  expectError([&] { fm::refineRig(*rig_, 0, bad_size); }, "cam2: image is 512x272, calibration says 1024x544");
  auto bad_type = one;
  bad_type[0][1] = cv::Mat(544, 1024, CV_8UC3, cv::Scalar::all(0));
  expectError([&] { fm::refineRig(*rig_, 0, bad_type); }, "cam1: image must be 8-bit single-channel");
  auto empty_image = one;
  empty_image[0][4] = cv::Mat();
  expectError([&] { fm::refineRig(*rig_, 0, empty_image); }, "cam4: image is empty");
  expectError([&] { fm::refineRig(*rig_, 0, one, {cv::Mat()}); }, "self_masks");
  std::vector<cv::Mat> masks(5);
  masks[3] = cv::Mat::zeros(10, 10, CV_8UC1);
  expectError([&] { fm::refineRig(*rig_, 0, one, masks); }, "self-mask of cam3");
  fm::RigRefinementConfig cfg;
  cfg.min_inliers = 0;
  expectError([&] { fm::refineRig(*rig_, 0, one, {}, cfg); }, "min_inliers");
}

// The tool on a bag: a perturbed calibration is corrected and written; usage
// errors and a featureless bag exit 2 without writing.
TEST(RefineRigTool, CorrectsACalibrationFromABag) {
  const std::string dir = "/tmp/fm_test_refine_rig_" + std::to_string(getpid());
  const std::string tool = FM_REFINE_RIG;
  int rc = 0;
  std::string out = run(std::string(FM_MAKE_DRIVE) + " --out " + dir + "/drive --camchain " + kCamchain +
                            " --mount " + kMount + " --duration 2 --rate 2 --gt-depth none",
                        &rc);
  ASSERT_EQ(rc, 0) << out;
  const fm::Rig truth = fm::loadKalibrRig(dir + "/drive/camchain.yaml", dir + "/drive/mount.yaml");
  fm::Rig bad = truth;
  for (int c = 1; c < 5; ++c) bad = perturbed(bad, 0, c, kAxes[c - 1], 0.4);
  fm::writeKalibrRig(bad, dir + "/bad_camchain.yaml", dir + "/bad_mount.yaml");
  const std::string args = " --bag " + dir + "/drive/drive.bag --camchain " + dir + "/bad_camchain.yaml --mount " +
                           dir + "/bad_mount.yaml --out " + dir + "/fixed_camchain.yaml";

  out = run(tool + args + " --mount-out " + dir + "/fixed_mount.yaml", &rc);
  std::printf("%s", out.c_str());
  ASSERT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("rms before"), std::string::npos) << out;
  EXPECT_NE(out.find("corrected 4 of 4 cameras"), std::string::npos) << out;
  const fm::Rig fixed = fm::loadKalibrRig(dir + "/fixed_camchain.yaml", dir + "/fixed_mount.yaml");
  for (int c = 1; c < 5; ++c)
    EXPECT_LT(angleDeg(relRotation(truth, 0, c), relRotation(fixed, 0, c)), kToleranceDeg) << "cam" << c;
  EXPECT_TRUE(fixed.cameras[2].T_base_cam.isApprox(
      fm::loadKalibrRig(dir + "/fixed_camchain.yaml", dir + "/bad_mount.yaml").cameras[2].T_base_cam, 1e-9));

  // Usage errors: exit 2, nothing written.
  std::remove((dir + "/fixed_camchain.yaml").c_str());
  for (const std::string& bad_args : {args + " --frames x", args + " --frames 0", args + " --every 2.5",
                                      args + " --bogus", args + " --frames", std::string(" --bag x.bag"),
                                      args + " --self-masks cam9=m.png"}) {
    out = run(tool + bad_args, &rc);
    EXPECT_EQ(rc, 2) << bad_args << "\n" << out;
    EXPECT_NE(out.find("usage"), std::string::npos) << out;
  }
  EXPECT_FALSE(exists(dir + "/fixed_camchain.yaml"));

  // A lens cap: black frame sets, too few matches, exit 2, nothing written.
  {
    rosbag::Bag bag(dir + "/black.bag", rosbag::bagmode::Write);
    for (int k = 0; k < 3; ++k) {
      for (int c = 0; c < 5; ++c) {
        sensor_msgs::Image im;
        im.header.stamp = ros::Time(100 + k);
        im.width = 1024, im.height = 544, im.step = 1024, im.encoding = "mono8";
        im.data.assign(1024 * 544, 0);
        bag.write("/cam" + std::to_string(c) + "/image_raw", im.header.stamp, im);
      }
    }
  }
  out = run(tool + " --bag " + dir + "/black.bag --camchain " + dir + "/bad_camchain.yaml --mount " + dir +
                "/bad_mount.yaml --out " + dir + "/fixed_camchain.yaml",
            &rc);
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("too few feature matches"), std::string::npos) << out;
  EXPECT_FALSE(exists(dir + "/fixed_camchain.yaml"));
  std::system(("rm -rf " + dir).c_str());
}

}  // namespace
