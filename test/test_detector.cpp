// Detector core: each head decoder on small models built here with known outputs
// (boxes worked out by hand, through the letterbox), per-class NMS, config and
// model errors, and the real COCO NanoDet on dog.jpg against hand-measured boxes.
#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <tuple>
#include <stdexcept>
#include <string>
#include <vector>

#include "fisheye_mapping/core/detection/detector.h"
#include "scratch_dir.h"

using namespace fisheye_mapping;
namespace fm = fisheye_mapping;

namespace {

// Removed when the test program ends.
std::string tmpDir() {
  static const fm::test::ScratchDir dir("/tmp/fm_test_detector_");
  return dir.path();
}

void writeText(const std::string& path, const std::string& text) {
  std::ofstream f(path);
  f << text;
}

// Writes a values file for make_const_onnx.py.
std::string valuesFile(const std::string& name, const std::vector<int>& shape, const std::vector<float>& v) {
  const std::string path = tmpDir() + "/" + name + ".txt";
  std::ofstream f(path);
  for (size_t i = 0; i < shape.size(); ++i) f << (i ? "," : "") << shape[i];
  f << "\n";
  for (float x : v) f << x << " ";
  return path;
}

// Builds an ONNX model whose outputs are the given tensors.
std::string constModel(const std::string& name, const std::string& input_shape,
                       const std::vector<std::string>& value_files) {
  const std::string out = tmpDir() + "/" + name + ".onnx";
  std::string cmd = "/usr/bin/python3 " FM_TEST_DIR "/make_const_onnx.py " + out + " " + input_shape;
  for (const auto& f : value_files) cmd += " " + f;
  if (std::system(cmd.c_str()) != 0) throw std::runtime_error("make_const_onnx.py failed: " + cmd);
  return out;
}

DetectorModelConfig smallConfig(DetectorHead head, const std::string& model, int in_w, int in_h) {
  DetectorModelConfig c;
  c.format = ModelFormat::Onnx;
  c.model_path = model;
  c.head = head;
  c.input_width = in_w;
  c.input_height = in_h;
  c.class_names = {"person", "car", "tree"};
  c.moving_classes = {"car"};
  c.score_threshold = 0.35f;
  c.nms_threshold = 0.5f;
  return c;
}

void expectBox(const Detection& d, const std::string& cls, float score, float x0, float y0, float x1, float y1,
               float tol = 1e-3f) {
  EXPECT_EQ(d.class_name, cls);
  EXPECT_NEAR(d.score, score, 1e-4);
  EXPECT_NEAR(d.x_min, x0, tol);
  EXPECT_NEAR(d.y_min, y0, tol);
  EXPECT_NEAR(d.x_max, x1, tol);
  EXPECT_NEAR(d.y_max, y1, tol);
}

// Rows (cx, cy, w, h, obj, p_person, p_car, p_tree) in network-input pixels of a 64x64 input.
const std::vector<std::vector<float>> kYoloRows = {
    {32, 32, 20, 10, 0.9f, 0.1f, 0.8f, 0.1f},  // car 0.72
    {33, 32, 20, 10, 0.9f, 0.1f, 0.7f, 0.1f},  // car 0.63, IoU 0.9 with the first: suppressed
    {32, 32, 20, 10, 0.9f, 0.1f, 0.0f, 0.9f},  // tree 0.81 at the same place: other class, kept
    {10, 50, 8, 8, 0.2f, 0.0f, 1.0f, 0.0f},    // objectness 0.2: below the threshold
    {10, 20, 8, 8, 1.0f, 0.0f, 0.5f, 0.0f},    // car 0.5
};

// A 128x64 grey image letterboxed into 64x64: scale 0.5, 16 px bands top and bottom.
// Input (x, y) -> image (2x, 2(y - 16)).
const cv::Mat kImage128x64(64, 128, CV_8UC1, cv::Scalar(90));

}  // namespace

TEST(Letterbox, MapsBackByHand) {
  const Letterbox lb = Letterbox::compute(1024, 544, 416, 416, true);
  EXPECT_FLOAT_EQ(lb.scale_x, 416.f / 1024.f);
  EXPECT_NEAR(lb.scale_y, 221.f / 544.f, 1e-6);  // 544 * 0.40625 = 221
  EXPECT_FLOAT_EQ(lb.pad_x, 0.f);
  EXPECT_FLOAT_EQ(lb.pad_y, 97.f);  // (416 - 221) / 2 = 97
  EXPECT_NEAR(lb.toImageX(208.f), 512.f, 1e-3);
  EXPECT_NEAR(lb.toImageY(97.f), 0.f, 1e-4);
  const Letterbox st = Letterbox::compute(1024, 544, 416, 416, false);
  EXPECT_NEAR(st.toImageY(416.f), 544.f, 1e-3);
}

TEST(Detector, InputBlobIsGreyReplicatedLetterboxedAndNormalised) {
  DetectorModelConfig c = smallConfig(DetectorHead::YoloV5, "", 64, 64);
  c.mean = cv::Scalar(10, 20, 30);
  c.std = cv::Scalar(2, 4, 5);
  c.swap_rb = false;
  c.pad_value = 114;
  Letterbox lb;
  const cv::Mat blob = makeInputBlob(kImage128x64, c, &lb);
  ASSERT_EQ(blob.dims, 4);
  EXPECT_EQ(blob.size[1], 3);
  EXPECT_EQ(blob.size[2], 64);
  const float* p = blob.ptr<float>();
  const int plane = 64 * 64;
  for (int ch = 0; ch < 3; ++ch) {
    const double m = c.mean[ch], s = c.std[ch];
    EXPECT_NEAR(p[ch * plane + 5 * 64 + 10], (114 - m) / s, 1e-5) << "pad band, channel " << ch;
    EXPECT_NEAR(p[ch * plane + 32 * 64 + 10], (90 - m) / s, 1e-5) << "image, channel " << ch;
  }
  EXPECT_THROW(makeInputBlob(cv::Mat(), c, nullptr), std::invalid_argument);
  EXPECT_THROW(makeInputBlob(cv::Mat(8, 8, CV_32FC1), c, nullptr), std::invalid_argument);
}

TEST(DetectorHeads, YoloV5DecodeNmsAndLetterbox) {
  std::vector<float> v;
  for (const auto& r : kYoloRows) v.insert(v.end(), r.begin(), r.end());
  const auto model = constModel("yolov5", "1,3,64,64", {valuesFile("yolov5", {1, 5, 8}, v)});
  Detector det(smallConfig(DetectorHead::YoloV5, model, 64, 64));
  const auto moving = det.detect(kImage128x64, true);
  ASSERT_EQ(moving.size(), 2u);
  // Row 0: input box (22, 27)-(42, 37) -> image (44, 22)-(84, 42).
  expectBox(moving[0], "car", 0.72f, 44, 22, 84, 42);
  // Row 4: input (6, 16)-(14, 24) -> image (12, 0)-(28, 16).
  expectBox(moving[1], "car", 0.5f, 12, 0, 28, 16);
  const auto all = det.detect(kImage128x64, false);
  ASSERT_EQ(all.size(), 3u);
  expectBox(all[0], "tree", 0.81f, 44, 22, 84, 42);
}

TEST(DetectorHeads, YoloV8DecodeTransposedLayout) {
  // [1, 4 + C, N]: one column per anchor, no objectness (scores are obj * p above).
  const int n = int(kYoloRows.size());
  std::vector<float> v(7 * n);
  for (int a = 0; a < n; ++a) {
    const auto& r = kYoloRows[a];
    for (int k = 0; k < 4; ++k) v[k * n + a] = r[k];
    for (int k = 0; k < 3; ++k) v[(4 + k) * n + a] = r[4] * r[5 + k];
  }
  const auto model = constModel("yolov8", "1,3,64,64", {valuesFile("yolov8", {1, 7, n}, v)});
  Detector det(smallConfig(DetectorHead::YoloV8, model, 64, 64));
  const auto all = det.detect(kImage128x64, false);
  ASSERT_EQ(all.size(), 3u);
  expectBox(all[0], "tree", 0.81f, 44, 22, 84, 42);
  expectBox(all[1], "car", 0.72f, 44, 22, 84, 42);
  expectBox(all[2], "car", 0.5f, 12, 0, 28, 16);
}

namespace {
// NanoDet on a 32x32 input, strides 8 and 16 (grids 4x4 and 2x2), reg_max 3 (4 bins).
// Stride 8, anchor 5 (gx 1, gy 1, centre (12, 12)): car 0.9; left bin 1 (8 px), top bin 0,
// right uniform bins (expectation 1.5 -> 12 px), bottom bin 2 (16 px): box (4, 12)-(24, 28).
// Stride 16, anchor 3 (gx 1, gy 1, centre (24, 24)): person 0.6, all uniform (24 px):
// box (0, 0)-(48, 48), clipped to the image. Image 64x64 -> input scale 0.5.
void nanodetTensors(std::vector<float>& cls8, std::vector<float>& reg8, std::vector<float>& cls16,
                    std::vector<float>& reg16) {
  cls8.assign(16 * 3, 0.01f);
  reg8.assign(16 * 16, 0.f);
  cls16.assign(4 * 3, 0.01f);
  reg16.assign(4 * 16, 0.f);
  cls8[5 * 3 + 1] = 0.9f;
  float* r = &reg8[5 * 16];
  r[0 * 4 + 1] = 30.f;  // left: bin 1
  r[1 * 4 + 0] = 30.f;  // top: bin 0
  r[3 * 4 + 2] = 30.f;  // bottom: bin 2 (right stays uniform)
  cls16[3 * 3 + 0] = 0.6f;
}
}  // namespace

TEST(DetectorHeads, NanoDetPerStrideOutputs) {
  std::vector<float> c8, r8, c16, r16;
  nanodetTensors(c8, r8, c16, r16);
  const auto model = constModel("nanodet", "1,3,32,32",
                                {valuesFile("n_c8", {1, 16, 3}, c8), valuesFile("n_r8", {1, 16, 16}, r8),
                                 valuesFile("n_c16", {1, 4, 3}, c16), valuesFile("n_r16", {1, 4, 16}, r16)});
  DetectorModelConfig c = smallConfig(DetectorHead::NanoDet, model, 32, 32);
  c.strides = {8, 16};
  c.reg_max = 3;
  c.center_offset = 0.5f;
  Detector det(c);
  const cv::Mat img(64, 64, CV_8UC1, cv::Scalar(0));
  const auto all = det.detect(img, false);
  ASSERT_EQ(all.size(), 2u);
  expectBox(all[0], "car", 0.9f, 8, 24, 48, 56, 1e-3f);
  expectBox(all[1], "person", 0.6f, 0, 0, 64, 64, 1e-3f);
  const auto moving = det.detect(img, true);
  ASSERT_EQ(moving.size(), 1u);
  EXPECT_EQ(moving[0].class_name, "car");
}

TEST(DetectorHeads, NanoDetMergedOutputAndCentreOffset) {
  std::vector<float> c8, r8, c16, r16;
  nanodetTensors(c8, r8, c16, r16);
  std::vector<float> merged;
  for (int i = 0; i < 16; ++i) {
    merged.insert(merged.end(), c8.begin() + 3 * i, c8.begin() + 3 * i + 3);
    merged.insert(merged.end(), r8.begin() + 16 * i, r8.begin() + 16 * i + 16);
  }
  for (int i = 0; i < 4; ++i) {
    merged.insert(merged.end(), c16.begin() + 3 * i, c16.begin() + 3 * i + 3);
    merged.insert(merged.end(), r16.begin() + 16 * i, r16.begin() + 16 * i + 16);
  }
  const auto model = constModel("nanodet_merged", "1,3,32,32", {valuesFile("n_m", {1, 20, 19}, merged)});
  DetectorModelConfig c = smallConfig(DetectorHead::NanoDet, model, 32, 32);
  c.strides = {8, 16};
  c.reg_max = 3;
  c.center_offset = 0.f;  // NanoDet-Plus convention: centres move by -0.5 stride
  Detector det(c);
  const auto all = det.detect(cv::Mat(64, 64, CV_8UC1, cv::Scalar(0)), false);
  ASSERT_EQ(all.size(), 2u);
  expectBox(all[0], "car", 0.9f, 0, 16, 40, 48, 1e-3f);  // (4-4, 12-4)-(24-4, 28-4) in input, x2
  // Wrong layout for the head: clear error.
  c.reg_max = 5;
  Detector bad(c);
  EXPECT_THROW(bad.detect(cv::Mat(64, 64, CV_8UC1, cv::Scalar(0))), std::runtime_error);
}

TEST(DetectorHeads, DarknetYoloLayer) {
  // 32x32 input; an 8x8 stride-8 convolution gives a 4x4 grid; one anchor (10 x 14 px),
  // 3 classes. Objectness logit = -10 + 10 * (mean of the 8x8x3 window in 0..1), so only
  // the cell holding a white block fires; class logits (-3, 3, -3) -> car 0.9526.
  const std::string cfg = tmpDir() + "/tiny.cfg", weights = tmpDir() + "/tiny.weights";
  writeText(cfg,
            "[net]\nwidth=32\nheight=32\nchannels=3\n\n"
            "[convolutional]\nfilters=8\nsize=8\nstride=8\npad=0\nactivation=linear\n\n"
            "[yolo]\nmask=0\nanchors=10,14\nclasses=3\nnum=1\n");
  {
    std::ofstream f(weights, std::ios::binary);
    const int32_t header[3] = {0, 2, 0};
    const int64_t seen = 0;
    f.write(reinterpret_cast<const char*>(header), sizeof(header));
    f.write(reinterpret_cast<const char*>(&seen), sizeof(seen));
    const float bias[8] = {0, 0, 0, 0, -10, -3, 3, -3};  // tx ty tw th obj c0 c1 c2
    f.write(reinterpret_cast<const char*>(bias), sizeof(bias));
    std::vector<float> w(8 * 3 * 8 * 8, 0.f);
    for (int k = 0; k < 3 * 64; ++k) w[4 * 3 * 64 + k] = 10.f / 64.f;  // objectness filter
    f.write(reinterpret_cast<const char*>(w.data()), w.size() * sizeof(float));
  }
  DetectorModelConfig c = smallConfig(DetectorHead::Darknet, weights, 32, 32);
  c.format = ModelFormat::Darknet;
  c.darknet_cfg = cfg;
  c.mean = cv::Scalar(0, 0, 0);
  c.std = cv::Scalar(255, 255, 255);
  Detector det(c);
  cv::Mat img(32, 32, CV_8UC1, cv::Scalar(0));
  img(cv::Rect(16, 8, 8, 8)).setTo(255);  // grid cell (2, 1)
  const auto all = det.detect(img, false);
  ASSERT_EQ(all.size(), 1u);
  // Centre ((2 + 0.5) / 4 * 32, (1 + 0.5) / 4 * 32) = (20, 12); size exp(0) * anchor = 10 x 14.
  const float p_car = 1.f / (1.f + std::exp(-3.f)), p_obj = 1.f / (1.f + std::exp(-20.f));
  expectBox(all[0], "car", p_car * p_obj, 15, 5, 25, 19, 1e-3f);
}

TEST(DetectorNms, PerClassByHand) {
  std::vector<Candidate> c = {{1, 0.9f, 0, 0, 10, 10},
                              {1, 0.8f, 1, 0, 11, 10},    // IoU 9/11 = 0.82 with the first
                              {1, 0.7f, 6, 0, 16, 10},    // IoU 4/16 = 0.25: kept
                              {2, 0.6f, 0, 0, 10, 10}};   // other class: kept
  const auto k = nmsPerClass(c, 0.5f);
  ASSERT_EQ(k.size(), 3u);
  EXPECT_FLOAT_EQ(k[0].score, 0.9f);
  EXPECT_FLOAT_EQ(k[1].score, 0.7f);
  EXPECT_FLOAT_EQ(k[2].score, 0.6f);
  EXPECT_EQ(nmsPerClass(c, 0.85f).size(), 4u);
}

TEST(DetectorNms, AcrossClassesByHand) {
  // A vehicle scored as two kinds (van 0.6, car 0.9 on the same box) is one detection.
  std::vector<Candidate> c = {{3, 0.6f, 0, 0, 10, 10},
                              {2, 0.9f, 1, 0, 11, 10},    // IoU 9/11 with the first: suppresses it
                              {3, 0.7f, 6, 0, 16, 10}};   // IoU 4/16 with the second: kept
  const auto k = nmsAcrossClasses(c, 0.5f);
  ASSERT_EQ(k.size(), 2u);
  EXPECT_EQ(k[0].class_id, 2);
  EXPECT_FLOAT_EQ(k[0].score, 0.9f);
  EXPECT_EQ(k[1].class_id, 3);
  EXPECT_FLOAT_EQ(k[1].score, 0.7f);
  EXPECT_EQ(nmsPerClass(c, 0.5f).size(), 3u);  // within classes nothing overlaps enough
}

TEST(DetectorConfigFile, ErrorsNameFileAndKey) {
  const std::string p = tmpDir() + "/bad.yaml";
  const auto expectError = [&](const std::string& yaml, const std::string& needle) {
    writeText(p, yaml);
    try {
      loadDetectorConfig(p);
      ADD_FAILURE() << "no error for: " << yaml;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
    }
  };
  const std::string ok = "format: onnx\nmodel: m.onnx\ninput_size: [64, 64]\nhead: yolov5\nclass_names: [car, tree]\n";
  expectError("format: tflite\n", "'format' must be onnx or darknet");
  expectError("format: onnx\n", "'model' is missing");
  expectError(ok + "moving_classes: [bus]\n", "'moving_classes' names 'bus'");
  expectError("format: onnx\nmodel: m\ninput_size: [60, 64]\nhead: yolov5\nclass_names: [a]\n", "'input_size'");
  expectError("format: onnx\nmodel: m\ninput_size: [64, 64]\nhead: yolox\nclass_names: [a]\n", "unknown head 'yolox'");
  expectError(ok + "score_threshold: 1.5\nmoving_classes: [car]\n", "'score_threshold'");
  expectError(ok + "moving_classes: [car]\nstd: [1, 0, 1]\n", "'std' must be positive");
  expectError("format: [\n", "detector model config");
  writeText(p, ok + "moving_classes: [car]\n");
  const auto c = loadDetectorConfig(p);
  EXPECT_EQ(c.model_path, tmpDir() + "/m.onnx");  // relative to the YAML's folder
  EXPECT_EQ(c.head, DetectorHead::YoloV5);
}

TEST(DetectorConfigFile, PathExpansion) {
  setenv("FM_TEST_VAR", "/opt/x", 1);
  unsetenv("FM_TEST_UNSET");
  EXPECT_EQ(expandPath("${FM_TEST_VAR}/m.onnx"), "/opt/x/m.onnx");
  EXPECT_EQ(expandPath("${FM_TEST_UNSET:-/a/${FM_TEST_VAR}}/m"), "/a//opt/x/m");
  EXPECT_EQ(expandPath("~/m"), std::string(std::getenv("HOME")) + "/m");
  EXPECT_THROW(expandPath("${FM_TEST_VAR"), std::runtime_error);
}

TEST(Detector, MissingAndCorruptModelsGiveClearErrors) {
  DetectorModelConfig c = smallConfig(DetectorHead::YoloV5, tmpDir() + "/does_not_exist.onnx", 64, 64);
  try {
    Detector d(c);
    ADD_FAILURE() << "missing model accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("does_not_exist.onnx"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
  }
  c.model_path = tmpDir() + "/corrupt.onnx";
  writeText(c.model_path, "this is not a protobuf, just text pretending to be a model");
  try {
    Detector d(c);
    ADD_FAILURE() << "corrupt model accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot load model"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("corrupt.onnx"), std::string::npos) << e.what();
  }
  c.model_path = tmpDir() + "/corrupt.weights";
  c.format = ModelFormat::Darknet;
  c.darknet_cfg = tmpDir() + "/corrupt.cfg";
  writeText(c.darknet_cfg, "[net]\nwidth=abc\n[convolutional]\nfilters=-1\n");
  writeText(c.model_path, "xx");
  EXPECT_THROW(Detector d(c), std::runtime_error);
}

// The real model made by scripts/setup: COCO NanoDet on dog.jpg (Debian's darknet package).
TEST(NanoDetCoco, FindsTruckAndBicycleInDogJpg) {
  const std::string yaml = FM_CONFIG_DIR "/detector/nanodet.yaml";
  const DetectorModelConfig cfg = loadDetectorConfig(yaml);
  const cv::Mat img = cv::imread("/usr/share/darknet/data/dog.jpg", cv::IMREAD_COLOR);
  if (img.empty()) GTEST_SKIP() << "/usr/share/darknet/data/dog.jpg missing (Debian package darknet)";
  if (!std::ifstream(cfg.model_path).good())
    GTEST_SKIP() << cfg.model_path << " missing: run scripts/setup (scripts/test makes it)";
  Detector det(cfg);
  // Boxes measured by hand on the 768x576 image.
  Detection truck, bicycle, dog;
  truck.x_min = 466, truck.y_min = 74, truck.x_max = 694, truck.y_max = 170;
  bicycle.x_min = 125, bicycle.y_min = 133, bicycle.x_max = 567, bicycle.y_max = 420;
  dog.x_min = 132, dog.y_min = 218, dog.x_max = 310, dog.y_max = 540;
  const auto check = [&](const std::vector<Detection>& dets, const Detection& truth, const std::string& cls,
                         float min_score) {
    const Detection* best = nullptr;
    for (const auto& d : dets)
      if (d.class_name == cls && (!best || boxIoU(d, truth) > boxIoU(*best, truth))) best = &d;
    ASSERT_NE(best, nullptr) << "no " << cls;
    EXPECT_GE(boxIoU(*best, truth), 0.5f) << cls << " box " << best->x_min << "," << best->y_min << " "
                                          << best->x_max << "," << best->y_max;
    EXPECT_GE(best->score, min_score) << cls;
  };
  const auto dets = det.detect(img, true);
  check(dets, truck, "truck", 0.3f);
  check(dets, bicycle, "bicycle", 0.5f);
  for (const auto& d : dets) EXPECT_NE(d.class_name, "dog") << "dog is not a moving class";
  const auto all = det.detect(img, false);
  check(all, dog, "dog", 0.3f);
  // The system's input: the same scene in grey (three equal channels) still gives the bicycle.
  cv::Mat grey;
  cv::cvtColor(img, grey, cv::COLOR_BGR2GRAY);
  check(det.detect(grey, true), bicycle, "bicycle", 0.4f);
}

// A stage config without a model, with and without threshold overrides, and
// model YAMLs with out-of-range thresholds (named with file, key and value).
TEST(DetectorStageConfig, LoadModelAppliesTheOverridesAndModelYamlsCheckTheirThresholds) {
  fm::DetectorStageConfig none;
  EXPECT_THROW(none.loadModel(), std::runtime_error);
  const std::string dir = ::testing::TempDir() + "/test_params_detector";
  std::filesystem::create_directories(dir);
  const std::string base =
      "format: onnx\nmodel: m.onnx\ninput_size: [64, 64]\nhead: yolov8\nclass_names: [car]\nmoving_classes: [car]\n";
  const std::string model = dir + "/thresholds.yaml";
  std::ofstream(model) << base << "score_threshold: 0.3\nnms_threshold: 0.5\n";
  fm::DetectorStageConfig c;
  c.model_config = model;
  const fm::DetectorModelConfig plain = c.loadModel(), direct = fm::loadDetectorConfig(model);
  EXPECT_FLOAT_EQ(plain.score_threshold, 0.3f);
  EXPECT_FLOAT_EQ(direct.score_threshold, 0.3f);
  EXPECT_FLOAT_EQ(plain.nms_threshold, 0.5f);
  c.score_threshold = 0.61f;
  c.nms_threshold = 0.42f;
  const fm::DetectorModelConfig over = c.loadModel();
  EXPECT_FLOAT_EQ(over.score_threshold, 0.61f);
  EXPECT_FLOAT_EQ(over.nms_threshold, 0.42f);
  EXPECT_EQ(over.class_names, direct.class_names);
  c.score_threshold = 1.5f;
  EXPECT_THROW(c.loadModel(), std::invalid_argument);
  // A model YAML with out-of-range thresholds: the file, the key and the value.
  for (const auto& [extra, key, value] : {std::make_tuple("nms_threshold: 0\n", "nms_threshold", "got 0"),
                                          std::make_tuple("nms_threshold: 1.5\n", "nms_threshold", "got 1.5"),
                                          std::make_tuple("score_threshold: 1\n", "score_threshold", "got 1"),
                                          std::make_tuple("score_threshold: -0.2\n", "score_threshold", "got -0.2")}) {
    const std::string p = dir + "/model.yaml";
    std::ofstream(p) << base << extra;
    try {
      fm::loadDetectorConfig(p);
      ADD_FAILURE() << "no error for " << extra;
    } catch (const std::runtime_error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(p), std::string::npos) << msg;
      EXPECT_NE(msg.find(std::string("'") + key + "'"), std::string::npos) << msg;
      EXPECT_NE(msg.find(value), std::string::npos) << msg;
    }
  }
  std::ofstream(dir + "/model.yaml") << base << "score_threshold: 0.2\nnms_threshold: 1\n";
  EXPECT_NO_THROW(fm::loadDetectorConfig(dir + "/model.yaml"));
}

