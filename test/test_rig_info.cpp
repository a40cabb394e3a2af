// The rig_info tool, run as a user would, against hand-computed numbers.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <sys/wait.h>

namespace {

struct Result {
  std::string out;
  int status;
};

// Runs rig_info with `args`, feeding `input` on stdin; captures stdout.
Result run(const std::string& args, const std::string& input = "", bool with_stderr = false) {
  const std::string in_path = "/tmp/fm_rig_info_test_input.txt";
  std::ofstream(in_path) << input;
  const std::string cmd = std::string(FM_RIG_INFO) + " " + args + " < " + in_path + (with_stderr ? " 2>&1" : " 2>/dev/null");
  FILE* pipe = popen(cmd.c_str(), "r");
  Result r{"", -1};
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), pipe)) > 0) r.out.append(buf, n);
  r.status = WEXITSTATUS(pclose(pipe));
  return r;
}

const std::string kRig = std::string("--camchain ") + FM_TEST_DATA_DIR +
                         "/two_camera_camchain.yaml --mount " + FM_TEST_DATA_DIR +
                         "/two_camera_mount.yaml";

TEST(RigInfo, ProjectsHandComputedPoints) {
  // cam0: unified xi = 1, f = 300, c = (512, 272).
  // (1,2,2): d = 3, m = (1, 2) / 5 -> (572, 392). (0,0,-1): the back axis.
  // (1,0,0) is 90 deg off-axis: d = 1, m = (1, 0) -> u = 512 + 300 = 812.
  // (0.5,0,0.5) is 45 deg off-axis: m = tan(22.5 deg) = 0.414213562373.
  const Result r = run(kRig + " --project cam0", "1 2 2\n0 0 -1\n1 0 0\n0.5 0 0.5\n");
  EXPECT_EQ(r.status, 0);
  EXPECT_EQ(r.out, "572.000000000 392.000000000\ninvalid\n812.000000000 272.000000000\n"
                   "636.264068712 272.000000000\n");
}

TEST(RigInfo, OutsideTheImageIsInvalid) {
  // (3,0,1) projects to u = 512 + 300 * 3 / (1 + sqrt(10)) = 728.2, inside;
  // (0,3,1) to v = 272 + 216.2 = 488.2, inside; (0,30,1) to v ~ 557 > 543.
  const Result r = run(kRig + " --project cam0", "0 30 1\n");
  EXPECT_EQ(r.out, "invalid\n");
}

TEST(RigInfo, UnprojectsHandComputedPixels) {
  // cam1: equidistant, f = 300: pixel (512 + 300 * pi / 2, 272) is 90 deg off
  // axis towards +x -> ray (1, 0, 0); the principal point -> (0, 0, 1).
  char line[128];
  std::snprintf(line, sizeof(line), "%.12f 272\n512 272\n", 512 + 150 * M_PI);
  const Result r = run(kRig + " --unproject cam1", line);
  EXPECT_EQ(r.status, 0);
  EXPECT_EQ(r.out, "1.000000000000 0.000000000000 0.000000000000\n"
                   "0.000000000000 0.000000000000 1.000000000000\n");
}

TEST(RigInfo, BadInputLinesSayInvalidAndFailTheExitStatus) {
  const Result r = run(kRig + " --project cam0", "1 2\nnot numbers\n1 2 2\n");
  EXPECT_EQ(r.out, "invalid\ninvalid\n572.000000000 392.000000000\n");
  EXPECT_EQ(r.status, 1);
  EXPECT_EQ(run(kRig + " --project cam7", "1 2 2\n").status, 2);
}

TEST(RigInfo, SummaryShowsFieldOfViewPositionsAndOverlap) {
  const Result r = run(kRig);
  ASSERT_EQ(r.status, 0) << r.out;
  // cam1 is equidistant with f = 300 over 1024 px centred at 512: the centre
  // row spans (512 + 511) / 300 rad = 195.4 deg; the centre column
  // (272 + 271) / 300 rad = 103.7 deg.
  EXPECT_NE(r.out.find("field of view: horizontal 195.4 deg, vertical 103.7 deg"),
            std::string::npos) << r.out;
  // cam0 (unified xi = 1, every direction but the back axis valid):
  // |u - 512| = 300 tan(theta / 2), so the row spans 2 atan(512/300) to the
  // left plus 2 atan(511/300) to the right.
  const double h0 = (2 * std::atan(512.0 / 300) + 2 * std::atan(511.0 / 300)) * 180 / M_PI;
  char expected[128];
  std::snprintf(expected, sizeof(expected), "field of view: horizontal %.1f deg", h0);
  EXPECT_NE(r.out.find(expected), std::string::npos) << expected << "\n" << r.out;
  EXPECT_NE(r.out.find("position in cam0 [m]:   0.5000   0.0000   0.0000  (baseline 0.5000)"),
            std::string::npos) << r.out;
  // cam1 in base_link: R (0.5, 0, 0) + (1.5, 0, 1.6) = (1.5, -0.5, 1.6).
  EXPECT_NE(r.out.find("position in base_link [m]:   1.5000  -0.5000   1.6000"), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("optical axis in base_link: yaw 0.0 deg, pitch 0.0 deg"), std::string::npos);
  // Each camera sees all of its own pixels.
  EXPECT_NE(r.out.find("    cam0   1.000"), std::string::npos) << r.out;
}

TEST(RigInfo, BadCalibrationNamesFileAndField) {
  const std::string args = std::string("--camchain ") + FM_TEST_DATA_DIR +
                           "/bad_camchain.yaml --mount " + FM_TEST_DATA_DIR +
                           "/two_camera_mount.yaml";
  const Result r = run(args, "", true);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.out.find("bad_camchain.yaml: cam0.intrinsics: fx must be positive"),
            std::string::npos) << r.out;
}

TEST(RigInfo, DefaultRigPrints) {
  const std::string args = std::string("--camchain ") + FM_CONFIG_DIR +
                           "/rig/default_camchain.yaml --mount " + FM_CONFIG_DIR +
                           "/rig/default_mount.yaml";
  const Result r = run(args);
  ASSERT_EQ(r.status, 0);
  EXPECT_NE(r.out.find("rig: 5 camera(s), base frame 'base_link'"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("cam4: omni-radtan 1024x544"), std::string::npos) << r.out;
}

}  // namespace
