// The shared option parsing of the tools (src/tools/cli.h) and the tools that
// use it: every bad value is named with its option, gets exit status 2, and
// the tool does no work; every tool answers --help with its full usage on
// stdout (exit 0) and an unknown option with its name on stderr (exit 2).
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "cli.h"
#include "tool_run.h"

namespace cli = fisheye_mapping::cli;

namespace {

using fisheye_mapping::test::ToolRun;
using fisheye_mapping::test::ToolRunApart;
using fisheye_mapping::test::runTool;
using fisheye_mapping::test::runToolApart;
ToolRun run(const std::string& cmd) { return runTool(cmd); }

template <typename F>
std::string usageError(F f) {
  try {
    f();
  } catch (const cli::UsageError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(Cli, WholeNumbersAreStrict) {
  EXPECT_EQ(cli::parseInt("--frames", "12", 1, 100), 12);
  EXPECT_EQ(cli::parseInt("--n", "-3", -5, 5), -3);
  EXPECT_EQ(usageError([] { cli::parseInt("--frames", "abc", 1, 100); }), "--frames needs a whole number, got 'abc'");
  EXPECT_EQ(usageError([] { cli::parseInt("--frames", "12abc", 1, 100); }), "--frames needs a whole number, got '12abc'");
  EXPECT_EQ(usageError([] { cli::parseInt("--frames", "1.5", 1, 100); }), "--frames needs a whole number, got '1.5'");
  EXPECT_EQ(usageError([] { cli::parseInt("--frames", "", 1, 100); }), "--frames needs a whole number, got ''");
  EXPECT_EQ(usageError([] { cli::parseInt("--frames", " 7", 1, 100); }), "--frames needs a whole number, got ' 7'");
  EXPECT_EQ(usageError([] { cli::parseInt("--every", "-3", 1, 1000000); }), "--every must lie in [1, 1000000], got -3");
  EXPECT_EQ(usageError([] { cli::parseInt("--n", "99999999999999999999999", 0, 10); }),
            "--n must lie in [0, 10], got 99999999999999999999999");
}

TEST(Cli, NumbersAreFiniteAndInRange) {
  EXPECT_DOUBLE_EQ(cli::parseDouble("--t", "0.25", 0, 1), 0.25);
  EXPECT_DOUBLE_EQ(cli::parseDouble("--t", "1e-3", 0, 1), 1e-3);
  EXPECT_EQ(usageError([] { cli::parseDouble("--t", "nan", 0, 1); }), "--t needs a number, got 'nan'");
  EXPECT_EQ(usageError([] { cli::parseDouble("--t", "inf", 0, 1); }), "--t needs a number, got 'inf'");
  EXPECT_EQ(usageError([] { cli::parseDouble("--t", "0x10", 0, 100); }), "--t needs a number, got '0x10'");
  EXPECT_EQ(usageError([] { cli::parseDouble("--t", "1e999", 0, 1); }), "--t must lie in [0, 1], got 1e999");
  EXPECT_EQ(usageError([] { cli::parseDouble("--t", "2", 0, 1); }), "--t must lie in [0, 1], got 2");
  EXPECT_EQ(usageError([] { cli::parsePositive("--range", "0", 1e6); }), "--range must be positive, got 0");
  EXPECT_EQ(cli::parseDoubleList("--t", "0.1,0.2", 0, 1).size(), 2u);
  EXPECT_EQ(usageError([] { cli::parseDoubleList("--t", "0.1,,0.2", 0, 1); }), "--t needs a number, got ''");
  EXPECT_EQ(usageError([] { cli::parseDoubleList("--t", "0.1,", 0, 1); }), "--t needs a number, got ''");
  int w = 0, h = 0;
  cli::parseSize("--size", "1280x800", 20000, &w, &h);
  EXPECT_EQ(w, 1280);
  EXPECT_EQ(h, 800);
  EXPECT_EQ(usageError([&] { cli::parseSize("--size", "100000x100000", 20000, &w, &h); }),
            "--size needs WxH with each side in [1, 20000] pixels, got '100000x100000'");
  EXPECT_EQ(usageError([&] { cli::parseSize("--size", "1280x800x", 20000, &w, &h); }),
            "--size needs WxH with each side in [1, 20000] pixels, got '1280x800x'");
}

TEST(Cli, FilesFoldersAndAtomicWrites) {
  const std::string dir = "/tmp/fm_test_cli_" + std::to_string(getpid());
  std::system(("rm -rf " + dir + " && mkdir -p " + dir).c_str());
  EXPECT_EQ(usageError([&] { cli::requireInputFile("--bag", dir); }), "--bag: " + dir + " is a directory, expected a file");
  EXPECT_EQ(usageError([&] { cli::requireInputFile("--bag", dir + "/x"); }), "--bag: " + dir + "/x: no such file");
  EXPECT_EQ(usageError([&] { cli::requireOutputFile("--csv", dir + "/a/b.csv"); }),
            "--csv: " + dir + "/a/b.csv: no such folder " + dir + "/a");
  std::ofstream(dir + "/file") << "x";
  EXPECT_EQ(usageError([&] { cli::prepareOutputDir("--out", dir + "/file"); }),
            "--out: " + dir + "/file exists and is not a folder");
  cli::prepareOutputDir("--out", dir + "/new/deep");
  // A failed write keeps the old file and leaves no temporary.
  std::ofstream(dir + "/keep.txt") << "old\n";
  EXPECT_THROW(cli::writeTextAtomically(dir + "/keep.txt",
                                        [](std::ostream& f) {
                                          f << "half";
                                          throw std::runtime_error("failed");
                                        }),
               std::runtime_error);
  std::ifstream keep(dir + "/keep.txt");
  std::string line;
  std::getline(keep, line);
  EXPECT_EQ(line, "old");
  size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) files += e.is_regular_file();
  EXPECT_EQ(files, 2u);  // file, keep.txt
  // A FIFO is refused (not blocked on) and stays.
  ASSERT_EQ(mkfifo((dir + "/pipe.csv").c_str(), 0644), 0);
  EXPECT_THROW(cli::writeTextAtomically(dir + "/pipe.csv", [](std::ostream& f) { f << "x"; }), std::runtime_error);
  EXPECT_TRUE(std::filesystem::is_fifo(dir + "/pipe.csv"));
  cli::writeTextAtomically(dir + "/keep.txt", [](std::ostream& f) { f << "new\n"; });
  std::ifstream now(dir + "/keep.txt");
  std::getline(now, line);
  EXPECT_EQ(line, "new");
  std::system(("rm -rf " + dir).c_str());
}

const std::string kRig = std::string(" --camchain ") + FM_CONFIG_DIR + "/rig/default_camchain.yaml --mount " +
                         FM_CONFIG_DIR + "/rig/default_mount.yaml";

TEST(ToolOptions, BadValuesAreNamedWithExitStatus2) {
  const struct {
    std::string cmd, expected;
  } cases[] = {
      {std::string(FM_TSDF_BENCHMARK) + " --out /tmp/x --frames abc", "tsdf_benchmark: --frames needs a whole number, got 'abc'"},
      {std::string(FM_TSDF_BENCHMARK) + " --out /tmp/x --frames 0", "tsdf_benchmark: --frames must lie in [1, 10000], got 0"},
      {std::string(FM_TSDF_BENCHMARK) + " --out /tmp/x --threads -1", "tsdf_benchmark: --threads must lie in [0, 1024], got -1"},
      {std::string(FM_TSDF_BENCHMARK) + " --out /tmp/x --drive 1e9", "tsdf_benchmark: --drive must lie in [0, 100000], got 1e9"},
      {std::string(FM_TSDF_BENCHMARK) + " --out /tmp/x --frames", "tsdf_benchmark: --frames needs a value"},
      {std::string(FM_TSDF_BENCHMARK) + " --out /etc/hostname", "tsdf_benchmark: --out: /etc/hostname exists and is not a folder"},
      {std::string(FM_DEPTH_BENCHMARK) + kRig + " --repeats 2x", "depth_benchmark: --repeats needs a whole number, got '2x'"},
      {std::string(FM_DEPTH_BENCHMARK) + kRig + " --band-rows -4", "depth_benchmark: --band-rows must lie in [1, 20000], got -4"},
      {std::string(FM_DEPTH_BENCHMARK) + kRig + " --repaets 2", "depth_benchmark: unknown option '--repaets'"},
      {std::string(FM_DEPTH_BENCHMARK) + " --camchain /tmp --mount /tmp", "depth_benchmark: --camchain: /tmp is a directory, expected a file"},
      {std::string(FM_DETECTOR_BENCHMARK) + " --config " + FM_CONFIG_DIR + "/detector/nanodet.yaml" + kRig + " --repeats 0",
       "detector_benchmark: --repeats must lie in [1, 10000], got 0"},
      {std::string(FM_DETECTOR_BENCHMARK) + " --config /tmp" + kRig,
       "detector_benchmark: --config: /tmp is a directory, expected a file"},
      {std::string(FM_DETECT_IMAGE) + " --config /tmp x.png", "detect_image: --config: /tmp is a directory, expected a file"},
      {std::string(FM_DETECT_IMAGE) + " x.png --config", "detect_image: --config needs a value"},
      {std::string(FM_DETECT_IMAGE) + " --config " + FM_CONFIG_DIR + "/detector/nanodet.yaml --out-dir /tmp/fm_no_such_dir x.png",
       "detect_image: --out-dir: /tmp/fm_no_such_dir: no such folder"},
  };
  for (const auto& c : cases) {
    const ToolRun r = run(c.cmd);
    EXPECT_EQ(r.status, 2) << c.cmd << "\n" << r.out;
    EXPECT_NE(r.out.find(c.expected), std::string::npos) << c.cmd << "\n" << r.out;
  }
}

// Every tool sits beside tsdf_benchmark (the package's lib folder; the test
// target depends on all of them).
std::string tool(const std::string& name) {
  const std::string any = FM_TSDF_BENCHMARK;
  return any.substr(0, any.rfind('/') + 1) + name;
}

// Each tool and the options its usage must document (all it takes).
const struct {
  std::string name;
  std::vector<std::string> options;
} kTools[] = {
    {"rig_info", {"--camchain", "--mount", "--psl", "--size", "--range", "--project", "--unproject"}},
    {"refine_rig",
     {"--bag", "--camchain", "--mount", "--out", "--mount-out", "--frames", "--every", "--self-masks",
      "--refine-translation", "--min-inliers"}},
    {"make_drive",
     {"--out", "--camchain", "--mount", "--preset", "--seed", "--duration", "--rate", "--speed", "--moving",
      "--jitter-ms", "--drop", "--pose-noise", "--gt-depth", "--calib-rot-deg", "--calib-trans-mm", "--gain-spread",
      "--offset-spread", "--gamma-spread", "--vignetting", "--read-noise", "--shot-noise", "--blur",
      "--asphalt-grain", "--clouds", "--realistic"}},
    {"depth_eval",
     {"synthetic", "vcharge", "vcharge-check", "--camchain", "--mount", "--out", "--preset", "--seed", "--frames",
      "--start", "--step", "--backend", "--device", "--max-range", "--realistic", "--sweep-camchain", "--data",
      "--camera", "--ground-z", "--label", "--depth-k", "--depth-k1", "--k"}},
    {"depth_benchmark", {"--camchain", "--mount", "--repeats", "--device", "--backends", "--band-rows"}},
    {"detect_image", {"--config", "--all-classes", "--grey", "--out-dir", "IMAGE"}},
    {"detector_benchmark", {"--config", "--camchain", "--mount", "--image", "--targets", "--repeats"}},
    {"map_accuracy", {"--cloud", "--mesh", "--ref", "--t", "--trail-tol", "--csv"}},
    {"map_tool", {"info", "check", "convert", "--max-weight", "--min-observations"}},
    {"offline_mapper",
     {"--bag", "--camchain", "--mount", "--out", "--config", "--config-dir", "--detector", "--frames", "--every",
      "--world", "--depth", "--save-depth", "--topic", "--sync", "--sync-tolerance", "--quiet", "nanodet",
      "ground_truth"}},
    {"paced_player",
     {"~bag", "~camchain", "~mount", "~image_topics", "~reference_topic", "~done_topic", "~timeout",
      "~wait_subscribers", "~start", "~require_tf", "~summary_file", "~hold"}},
    {"plane_sweep_depth",
     {"--camchain", "--mount", "--reference", "--config", "--set", "--image", "--mask", "--out", "--bag", "--topic",
      "--max-sets"}},
    {"tsdf_benchmark", {"--out", "--frames", "--threads", "--drive"}},
    {"param_docs", {"docs/parameters.md"}},
    {"detector_model", {"DETECTOR", "--model", "--finetuned-model", "--config-dir", "--list", "nanodet", "finetuned"}},
};

TEST(ToolOptions, HelpPrintsTheFullUsageOnStdout) {
  for (const auto& t : kTools) {
    for (const char* flag : {" --help", " -h"}) {
      const ToolRunApart r = runToolApart(tool(t.name) + flag);
      EXPECT_EQ(r.status, 0) << t.name << flag << "\n" << r.out << r.err;
      EXPECT_EQ(r.out.rfind("usage: ", 0), 0u) << t.name << flag << "\n" << r.out;
      EXPECT_EQ(r.err, "") << t.name << flag;
      for (const auto& o : t.options) EXPECT_NE(r.out.find(o), std::string::npos) << t.name << ": no " << o;
    }
  }
}

TEST(ToolOptions, UnknownOptionsAreNamedWithExitStatus2) {
  for (const auto& t : kTools) {
    // depth_eval wants its mode first; map_tool its command.
    const std::string pre = t.name == "depth_eval" ? " synthetic" : t.name == "map_tool" ? " info x.fmtsdf" : "";
    const ToolRunApart r = runToolApart(tool(t.name) + pre + " --no-such-option");
    EXPECT_EQ(r.status, 2) << t.name << "\n" << r.out << r.err;
    EXPECT_EQ(r.err.rfind(t.name + ": unknown option '--no-such-option'", 0), 0u) << t.name << "\n" << r.err;
    EXPECT_NE(r.err.find("usage: "), std::string::npos) << t.name << "\n" << r.err;
    EXPECT_EQ(r.out, "") << t.name;
  }
}

TEST(ToolOptions, AMissingValueNamesTheOption) {
  const struct {
    std::string tool, args;
  } cases[] = {
      {"rig_info", "--range"},          {"refine_rig", "--bag"},
      {"make_drive", "--seed"},         {"depth_eval", "synthetic --frames"},
      {"depth_benchmark", "--repeats"}, {"detect_image", "--config"},
      {"detector_benchmark", "--image"}, {"map_accuracy", "--csv"},
      {"map_tool", "--max-weight"},     {"offline_mapper", "--sync-tolerance"},
      {"plane_sweep_depth", "--bag"},   {"tsdf_benchmark", "--drive"},
      {"detector_model", "nanodet --model"},
  };
  for (const auto& c : cases) {
    const ToolRunApart r = runToolApart(tool(c.tool) + " " + c.args);
    const std::string option = c.args.substr(c.args.rfind(' ') + 1);
    EXPECT_EQ(r.status, 2) << c.tool << " " << c.args << "\n" << r.err;
    EXPECT_EQ(r.err.rfind(c.tool + ": " + option + " needs a value\n", 0), 0u) << c.tool << "\n" << r.err;
  }
}

// depth_eval reads its numbers strictly (it used std::stoi: "8abc" was 8).
TEST(ToolOptions, DepthEvalRefusesMalformedNumbers) {
  const std::string base = tool("depth_eval") + " synthetic --camchain " + FM_CONFIG_DIR +
                           "/rig/default_camchain.yaml --mount " + FM_CONFIG_DIR + "/rig/default_mount.yaml --out " +
                           ::testing::TempDir() + "/depth_eval_numbers";
  const struct {
    std::string args, expected;
  } cases[] = {
      {" --frames 8abc", "depth_eval: --frames needs a whole number, got '8abc'\n"},
      {" --frames 0", "depth_eval: --frames must lie in [1, 100000], got 0\n"},
      {" --max-range -1", "depth_eval: --max-range must lie in [0.1, 10000], got -1\n"},
      {" --seed 1.5", "depth_eval: --seed needs a whole number, got '1.5'\n"},
      {" --wall-planes 2x", "depth_eval: --wall-planes needs a whole number, got '2x'\n"},
      {" --step 1s", "depth_eval: --step needs a number, got '1s'\n"},
      {" --set filter_infinity", "depth_eval: --set expects NAME=VALUE, got 'filter_infinity'\n"},
      {" --set filter_infinty=true", "depth_eval: --set: unknown parameter 'filter_infinty' in section 'depth'"},
  };
  for (const auto& c : cases) {
    const ToolRunApart r = runToolApart(base + c.args);
    EXPECT_EQ(r.status, 2) << c.args << "\n" << r.err;
    EXPECT_EQ(r.err.substr(0, c.expected.size()), c.expected) << c.args << "\n" << r.err;
  }
}

}  // namespace
