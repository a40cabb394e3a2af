// The rig_info tool, run as a user would, against hand-computed numbers.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

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

// Writes `text` to a file in /tmp and returns its path.
std::string writeTmp(const std::string& name, const std::string& text) {
  const std::string path = "/tmp/fm_rig_info_test_" + std::to_string(getpid()) + "_" + name;
  std::ofstream(path) << text;
  return path;
}

std::string readFile(const std::string& path) {
  std::ifstream f(path);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const size_t at = text.find(from);
  if (at == std::string::npos) throw std::logic_error("test setup: '" + from + "' not found");
  return text.replace(at, from.size(), to);
}

const std::string kChain = std::string(FM_TEST_DATA_DIR) + "/two_camera_camchain.yaml";
const std::string kMount = std::string(FM_TEST_DATA_DIR) + "/two_camera_mount.yaml";

TEST(RigInfo, HostileCalibrationsAreRefusedWithExitStatus2) {
  const std::string chain = readFile(kChain);
  const std::string big_key = writeTmp("big_key.yaml", replaced(chain, "cam1:", "cam2147483648:"));
  const std::string huge = writeTmp("huge.yaml", replaced(chain, "resolution: [1024, 544]", "resolution: [100000, 100000]"));
  const std::string fx = writeTmp("fx.yaml", replaced(chain, "[1.0, 300.0, 300.0,", "[1.0, 1e300, 1e300,"));
  const std::string shared =
      writeTmp("shared_mount.yaml", replaced(readFile(kMount), "cam1: cam1_optical", "cam1: cam0_optical"));
  const struct {
    std::string args, expected;
  } cases[] = {
      {"--camchain " + big_key + " --mount " + kMount,
       "rig_info: " + big_key + ": cam2147483648: camera index out of range: a rig has at most 64 cameras (cam0 ... cam63)\n"},
      {"--camchain /tmp --mount " + kMount, "rig_info: --camchain: /tmp is a directory, expected a file\n"},
      {"--camchain " + kChain + " --mount /tmp", "rig_info: --mount: /tmp is a directory, expected a file\n"},
      {"--camchain " + huge + " --mount " + kMount,
       "rig_info: " + huge + ": cam0.resolution: resolution must be at most 20000x20000 pixels, got 100000x100000\n"},
      {"--camchain " + fx + " --mount " + kMount,
       "rig_info: " + fx + ": cam0.intrinsics: fx must lie in (0, 1e+06] pixels, got 1e+300\n"},
      {"--camchain " + kChain + " --mount " + shared,
       "rig_info: " + shared + ": frame_ids.cam1: frame 'cam0_optical' is also cam0's; each camera needs its own tf frame\n"},
      {"--psl /tmp --size 1280x800", "rig_info: --psl: /tmp is a directory, expected a file\n"},
      {"--psl x.txt --size 100000x100000",
       "rig_info: --size needs WxH with each side in [1, 20000] pixels, got '100000x100000'\n"},
      {"--psl x.txt --size 1280x800junk",
       "rig_info: --size needs WxH with each side in [1, 20000] pixels, got '1280x800junk'\n"},
      {kRig + " --range abc", "rig_info: --range needs a number, got 'abc'\n"},
      {kRig + " --range -5", "rig_info: --range must be positive, got -5\n"},
      {kRig + " --range", "rig_info: --range needs a value\n"},
  };
  for (const auto& c : cases) {
    const Result r = run(c.args, "", true);
    EXPECT_EQ(r.status, 2) << c.args << "\n" << r.out;
    EXPECT_EQ(r.out.substr(0, c.expected.size()), c.expected) << c.args;
  }
}

TEST(RigInfo, LargestCameraSummaryIsQuick) {
  // 20000 x 20000 pixels, the limit: the field of view is sampled at
  // 2048 x 2048 (same angles), so the summary takes about a second, not minutes.
  const std::string chain = writeTmp(
      "largest.yaml", "cam0:\n  camera_model: omni\n  intrinsics: [1.0, 5859.375, 5859.375, 9999.5, 9999.5]\n"
                     "  distortion_model: none\n  resolution: [20000, 20000]\n");
  const auto t0 = std::chrono::steady_clock::now();
  const std::string mount = writeTmp("largest_mount.yaml", "T_base_cam0: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n");
  const Result r = run("--camchain " + chain + " --mount " + mount);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_LT(s, 20.0);
  EXPECT_NE(r.out.find("(sampled at 2048x2048)"), std::string::npos) << r.out;
}

TEST(RigInfo, HugeAndNonFinitePointsAreInvalidNotThePrincipalPoint) {
  const Result r = run(kRig + " --project cam0", "1e155 1e155 1e155\n1 2 2\nnan 1 1\n1 inf 1\n1e400 0 1\n");
  EXPECT_EQ(r.out, "invalid\n572.000000000 392.000000000\ninvalid\ninvalid\ninvalid\n");
  EXPECT_EQ(r.status, 1);  // nan, inf and 1e400 are not finite numbers: bad lines
  const Result u = run(kRig + " --unproject cam0", "1e300 1e300\n512 272\n");
  EXPECT_EQ(u.out, "invalid\n0.000000000000 0.000000000000 1.000000000000\n");
  EXPECT_EQ(u.status, 0);
}

TEST(RigInfo, OverlongLinesAreRefused) {
  const Result r = run(kRig + " --project cam0", std::string(10000, '1') + "\n1 2 2\n", true);
  EXPECT_NE(r.out.find("rig_info: line 1: longer than 4096 characters\n"), std::string::npos) << r.out.substr(0, 300);
  EXPECT_NE(r.out.find("invalid\n572.000000000 392.000000000\n"), std::string::npos);
  EXPECT_EQ(r.status, 1);
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

// Issue 28: a FIFO given as the camchain is refused at once (it blocked
// forever); an absurd principal point or fx/fy ratio is refused naming the
// camera and the field; hexadecimal coordinates are not numbers; --project ''
// is a usage error, not the summary.
TEST(RigInfo, FifoCamchainIsRefusedWithoutBlocking) {
  const std::string fifo = "/tmp/fm_test_rig_info_fifo_" + std::to_string(getpid());
  std::remove(fifo.c_str());
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  const auto t0 = std::chrono::steady_clock::now();
  // timeout: a regression blocks in open(); the test then fails instead of hanging.
  const Result r = run("--camchain " + fifo + " --mount " + kMount, "", true);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::remove(fifo.c_str());
  EXPECT_EQ(r.status, 2) << r.out;
  EXPECT_EQ(r.out, "rig_info: --camchain: " + fifo + " is a FIFO (named pipe), not a regular file\n");
  EXPECT_LT(s, 5.0);
  const Result dev = run("--camchain /dev/zero --mount " + kMount, "", true);
  EXPECT_EQ(dev.status, 2);
  EXPECT_EQ(dev.out, "rig_info: --camchain: /dev/zero is a character device, not a regular file\n");
}

TEST(RigInfo, AbsurdPrincipalPointAndFocalRatioNameCameraAndField) {
  const std::string chain = readFile(kChain);
  const std::string far_cx = writeTmp("far_cx.yaml", replaced(chain, "[1.0, 300.0, 300.0, 512.0, 272.0]", "[1.0, 300.0, 300.0, 100000.0, 272.0]"));
  const std::string neg_cy = writeTmp("neg_cy.yaml", replaced(chain, "[300.0, 300.0, 512.0, 272.0]", "[300.0, 300.0, 512.0, -40.0]"));
  const std::string ratio = writeTmp("ratio.yaml", replaced(chain, "[1.0, 300.0, 300.0,", "[1.0, 520.0, 1.5,"));
  const struct {
    std::string chain, expected;
  } cases[] = {
      {far_cx, far_cx + ": cam0.intrinsics: cx 100000 is outside the image: the principal point must lie in [-0.5, 1023.5] for width 1024"},
      {neg_cy, neg_cy + ": cam1.intrinsics: cy -40 is outside the image: the principal point must lie in [-0.5, 543.5] for height 544"},
      {ratio, ratio + ": cam0.intrinsics: fx 520 and fy 1.5 differ by more than a factor of 10 (fx/fy = 346.667)"},
  };
  for (const auto& c : cases) {
    const Result r = run("--camchain " + c.chain + " --mount " + kMount, "", true);
    EXPECT_EQ(r.status, 2) << r.out;
    EXPECT_EQ(r.out, "rig_info: " + c.expected + "\n");
  }
}

TEST(RigInfo, HexadecimalCoordinatesAreNotNumbers) {
  const Result r = run(kRig + " --project cam0", "0x10 0 1\n1 2 2\n0x1p3 1 1\n", true);
  EXPECT_NE(r.out.find("rig_info: line 1: expected 'x y z' (finite numbers), got '0x10 0 1'"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("rig_info: line 3:"), std::string::npos) << r.out;
  EXPECT_EQ(r.status, 1);
  const Result out = run(kRig + " --project cam0", "0x10 0 1\n1 2 2\n");
  EXPECT_EQ(out.out, "invalid\n572.000000000 392.000000000\n");
}

TEST(RigInfo, EmptyFilterCameraIsAUsageError) {
  for (const std::string opt : {"--project", "--unproject"}) {
    const Result r = run(kRig + " " + opt + " ''", "1 2 2\n", true);
    EXPECT_EQ(r.status, 2) << r.out;
    EXPECT_EQ(r.out.rfind("rig_info: " + opt + " needs a camera name, got ''\n", 0), 0u) << r.out;
  }
}
