// detector_eval on a hand-made YOLO folder with a constant-output model
// (make_const_onnx.py, yolov5 head): every image gets the same five detections,
// so precision, recall and AP are worked out by hand below; the bad items of the
// folder must be named and skipped, not counted.
#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "scratch_dir.h"
#include "tool_run.h"

using fisheye_mapping::test::runTool;
using fisheye_mapping::test::runToolApart;

namespace {

// Removed when the test program ends.
std::string tmpDir() {
  static const fisheye_mapping::test::ScratchDir dir("/tmp/fm_test_detector_eval_");
  return dir.path();
}

void writeText(const std::string& path, const std::string& text) {
  std::ofstream f(path);
  f << text;
}

// Detections of a 64x64 yolov5 input (cx, cy, w, h input pixels, objectness, p_car). The
// 128x64 image is letterboxed at scale 0.5 with 16 px bands: image = (2x, 2(y - 16)).
//   D1 0.9: image x 30..50,  y 16..48 (32 tall)  = G1 exactly: TP
//   D2 0.8: image x 90..110, y 16..48            IoU 0.24 with G4: FP
//   D3 0.6: image x 74..86,  y 20..36 (16 tall)  = G3, a short box: ignored
//   D4 0.5: image x 16..24,  y 4..12  (8 tall)   unmatched but short: ignored
//   D5 0.2: image x 50..70,  y 32..64            = G2: TP below the 0.35 threshold (AP only)
const char* kRows =
    "1,5,6\n"
    "20 32 10 16 0.9 1\n"
    "50 32 10 16 0.8 1\n"
    "40 30 6 8 0.6 1\n"
    "10 20 4 4 0.5 1\n"
    "30 40 10 16 0.2 1\n";

// G1, G2, G3 (16 px tall), G4 (30 px tall, missed), normalised to 128x64.
const char* kLabels =
    "0 0.3125 0.5 0.15625 0.5\n"
    "0 0.46875 0.75 0.15625 0.5\n"
    "0 0.625 0.4375 0.09375 0.25\n"
    "0 0.859375 0.390625 0.15625 0.46875\n";

struct Fixture {
  std::string config, folder;
};

const Fixture& fixture() {
  static Fixture fx;
  if (!fx.config.empty()) return fx;
  const std::string d = tmpDir();
  writeText(d + "/rows.txt", kRows);
  const std::string model = d + "/const.onnx";
  const std::string cmd = "/usr/bin/python3 " FM_TEST_DIR "/make_const_onnx.py " + model + " 1,3,64,64 " + d + "/rows.txt";
  if (std::system(cmd.c_str()) != 0) throw std::runtime_error("make_const_onnx.py failed: " + cmd);
  fx.config = d + "/model.yaml";
  writeText(fx.config,
            "format: onnx\nmodel: const.onnx\ninput_size: [64, 64]\nhead: yolov5\nclass_names: [car]\n"
            "moving_classes: [car]\nscore_threshold: 0.35\nnms_threshold: 0.5\nletterbox: true\n");
  fx.folder = d + "/set";
  for (const char* sub : {"/images", "/labels"}) std::filesystem::create_directories(fx.folder + sub);
  writeText(fx.folder + "/classes.txt", "car\n");
  const cv::Mat grey(64, 128, CV_8UC1, cv::Scalar(90));
  const auto item = [&](const std::string& name, const cv::Mat& img, const std::string& labels) {
    cv::imwrite(fx.folder + "/images/" + name + ".png", img);
    writeText(fx.folder + "/labels/" + name + ".txt", labels);
  };
  item("a_good", grey, kLabels);
  // Bad items: each would change the counts if it were used.
  item("b_empty", grey, "\n");
  item("c_class", grey, std::string(kLabels) + "3 0.5 0.5 0.1 0.1\n");
  item("d_outside", grey, "0 0.3125 0.5 0.15625 0.5\n0 0.98 0.5 0.1 0.5\n");
  item("e_size", cv::Mat(64, 64, CV_8UC1, cv::Scalar(90)), kLabels);
  return fx;
}

std::string eval(const std::string& extra) {
  return std::string(FM_DETECTOR_EVAL) + " --config " + fixture().config + " " + fixture().folder + " " + extra;
}

}  // namespace

TEST(DetectorEval, HandComputedPrecisionRecallAp) {
  const auto r = runToolApart(eval(""));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  // Counted: G1, G2, G4. At 0.35: D1 TP, D2 FP (D3, D4 ignored) -> precision 1/2, recall 1/3.
  // AP: ranked D1 TP, D2 FP, D5 TP: recall 1/3, 1/3, 2/3 at precision 1, 1/2, 2/3;
  // envelope 1, 2/3, 2/3 -> AP = 1/3 * 1 + 1/3 * 2/3 = 0.556.
  EXPECT_NE(r.out.find("images 1 (skipped 4:"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("vehicles >= 24 px tall: 3 (shorter, ignored: 1)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("precision 0.500 recall 0.333 AP50 0.556 (TP 1 FP 1 FN 2)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("time per frame"), std::string::npos) << r.out;
}

TEST(DetectorEval, BadItemsNamedWithFileAndLine) {
  const auto r = runToolApart(eval(""));
  const std::string labels = fixture().folder + "/labels/";
  EXPECT_NE(r.err.find(labels + "b_empty.txt: no boxes"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(labels + "c_class.txt:5: class id 3 is not in classes.txt (0..0)"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(labels + "d_outside.txt:2: box x 0.93..1.03"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("e_size.png: 64x64, expected 128x64"), std::string::npos) << r.err;
  EXPECT_NE(r.out.find("1 box outside image, 1 class id out of range, 1 empty label file, 1 wrong image size"),
            std::string::npos)
      << r.out;
}

TEST(DetectorEval, ScoreThresholdAndMinHeight) {
  // At 0.1, D5 counts too: TP 2 FP 1.
  auto r = runTool(eval("--score-threshold 0.1"));
  EXPECT_NE(r.out.find("precision 0.667 recall 0.667 AP50 0.556 (TP 2 FP 1 FN 1)"), std::string::npos) << r.out;
  // Boxes from 10 px: G3 counts and D3 matches it; D4 (8 px) stays ignored. Ranked D1 TP,
  // D2 FP, D3 TP, D5 TP over 4: recall 1/4, 1/4, 2/4, 3/4 at envelope 1, 3/4, 3/4, 3/4
  // -> AP = 1/4 * 1 + 2/4 * 3/4 = 0.625.
  r = runTool(eval("--min-height 10"));
  EXPECT_NE(r.out.find("vehicles >= 10 px tall: 4 (shorter, ignored: 0)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("precision 0.667 recall 0.500 AP50 0.625 (TP 2 FP 1 FN 2)"), std::string::npos) << r.out;
}

TEST(DetectorEval, SweptThresholdsMatchRunsAtEachThreshold) {
  // One run, three more thresholds: at 0.10 D5 counts (TP 2 FP 1, as the run at 0.1
  // above); at 0.85 only D1 (TP 1, precision 1, recall 1/3); at 0.95 nothing
  // (precision 1 by convention, recall 0). The operating line and AP stay those of
  // the run without the sweep, although the detector now runs down to 0.1.
  auto r = runTool(eval("--sweep-thresholds 0.1,0.85,0.95 --ap-threshold 0.3"));
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("at score 0.10: precision 0.667 recall 0.667 (TP 2 FP 1 FN 1)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("at score 0.85: precision 1.000 recall 0.333 (TP 1 FP 0 FN 2)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("at score 0.95: precision 1.000 recall 0.000 (TP 0 FP 0 FN 3)"), std::string::npos) << r.out;
  // Without D5 in the ranking (AP from 0.3): D1 TP, D2 FP over 3 -> AP = 1/3.
  EXPECT_NE(r.out.find("precision 0.500 recall 0.333 AP50 0.333 (TP 1 FP 1 FN 2)"), std::string::npos) << r.out;
  // The same figures as separate runs at each threshold.
  r = runTool(eval("--score-threshold 0.85"));
  EXPECT_NE(r.out.find("precision 1.000 recall 0.333"), std::string::npos) << r.out;
  r = runTool(eval("--sweep-thresholds 0.2,"));
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.out.find("--sweep-thresholds needs a number"), std::string::npos) << r.out;
}

TEST(DetectorEval, UsageErrors) {
  auto r = runTool(std::string(FM_DETECTOR_EVAL) + " --help");
  EXPECT_EQ(r.status, 0);
  EXPECT_NE(r.out.find("usage: detector_eval"), std::string::npos);
  r = runTool(eval("--bogus"));
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.out.find("unknown option '--bogus'"), std::string::npos) << r.out;
  r = runTool(eval("--iou 2"));
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.out.find("--iou must lie in"), std::string::npos) << r.out;
  r = runTool(std::string(FM_DETECTOR_EVAL) + " --config " + fixture().config + " /nonexistent_dir");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.out.find("/nonexistent_dir: no such folder"), std::string::npos) << r.out;
  r = runTool(std::string(FM_DETECTOR_EVAL) + " --config " + fixture().config + " " + tmpDir());
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.out.find("classes.txt: missing"), std::string::npos) << r.out;
}
