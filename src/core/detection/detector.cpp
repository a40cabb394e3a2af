#include "fisheye_mapping/core/detection/detector.h"
#include "fisheye_mapping/core/common/safe_open.h"

#include "fisheye_mapping/core/common/param_table.h"

#include <opencv2/dnn.hpp>
#include <opencv2/imgproc.hpp>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>

namespace fisheye_mapping {

namespace {

std::string dirOf(const std::string& path) {
  const auto slash = path.find_last_of('/');
  return slash == std::string::npos ? std::string(".") : path.substr(0, slash);
}

// Why `path` cannot be a model file ("" when it can): a regular file of at
// most kMaxModelFileBytes, opened without blocking (common/safe_open.h).
std::string modelFileProblem(const std::string& path) { return regularFileProblem(path, kMaxModelFileBytes); }

std::string number(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// The thresholds' ranges (model YAML and stage overrides alike).
bool scoreThresholdOk(double v) { return v > 0.0 && v < 1.0; }
bool nmsThresholdOk(double v) { return v > 0.0 && v <= 1.0; }

}  // namespace

std::string expandPath(const std::string& in) {
  std::string out;
  size_t i = 0;
  if (!in.empty() && in[0] == '~' && (in.size() == 1 || in[1] == '/')) {
    const char* home = std::getenv("HOME");
    out = home ? home : "";
    i = 1;
  }
  while (i < in.size()) {
    if (in.compare(i, 2, "${") != 0) {
      out += in[i++];
      continue;
    }
    // Find the matching brace (defaults may nest ${...}).
    size_t depth = 1, j = i + 2;
    for (; j < in.size() && depth > 0; ++j) {
      if (in.compare(j, 2, "${") == 0) {
        ++depth;
        ++j;
      } else if (in[j] == '}') {
        --depth;
      }
    }
    if (depth != 0) throw std::runtime_error("unterminated ${ in path '" + in + "'");
    const std::string body = in.substr(i + 2, j - 1 - (i + 2));
    const auto sep = body.find(":-");
    const std::string name = body.substr(0, sep);
    const char* value = std::getenv(name.c_str());
    if (value && *value) {
      out += value;
    } else if (sep != std::string::npos) {
      out += expandPath(body.substr(sep + 2));
    }
    i = j;
  }
  return out;
}

const char* headName(DetectorHead head) {
  switch (head) {
    case DetectorHead::Darknet: return "darknet";
    case DetectorHead::YoloV5: return "yolov5";
    case DetectorHead::YoloV8: return "yolov8";
    case DetectorHead::NanoDet: return "nanodet";
  }
  return "?";
}

DetectorHead parseHead(const std::string& name) {
  for (DetectorHead h : {DetectorHead::Darknet, DetectorHead::YoloV5, DetectorHead::YoloV8, DetectorHead::NanoDet})
    if (name == headName(h)) return h;
  throw std::runtime_error("unknown head '" + name + "' (darknet, yolov5, yolov8, nanodet)");
}

DetectorModelConfig loadDetectorConfig(const std::string& yaml_path) {
  YAML::Node root;
  const std::string text = readRegularFile(yaml_path, kMaxCalibrationFileBytes, "detector model config");
  try {
    root = YAML::Load(text);
  } catch (const std::exception& e) {
    throw std::runtime_error("detector model config " + yaml_path + ": " + e.what());
  }
  const auto fail = [&](const std::string& key, const std::string& why) {
    return std::runtime_error("detector model config " + yaml_path + ": '" + key + "' " + why);
  };
  if (!root.IsMap()) throw std::runtime_error("detector model config " + yaml_path + ": not a YAML map");
  const std::string base = dirOf(yaml_path);
  const auto resolve = [&](const std::string& p) {
    std::string e = expandPath(p);
    return (!e.empty() && e[0] != '/') ? base + "/" + e : e;
  };
  DetectorModelConfig c;
  try {
    const auto req = [&](const char* key) {
      if (!root[key]) throw fail(key, "is missing");
      return root[key];
    };
    const std::string format = req("format").as<std::string>();
    if (format == "onnx") c.format = ModelFormat::Onnx;
    else if (format == "darknet") c.format = ModelFormat::Darknet;
    else throw fail("format", "must be onnx or darknet, not '" + format + "'");
    c.model_path = resolve(req("model").as<std::string>());
    if (c.format == ModelFormat::Darknet) c.darknet_cfg = resolve(req("darknet_cfg").as<std::string>());
    const YAML::Node size = req("input_size");
    if (!size.IsSequence() || size.size() != 2) throw fail("input_size", "must be [width, height]");
    c.input_width = size[0].as<int>();
    c.input_height = size[1].as<int>();
    if (c.input_width <= 0 || c.input_height <= 0 || c.input_width % 8 || c.input_height % 8)
      throw fail("input_size", "must be positive multiples of 8");
    try {
      c.head = parseHead(req("head").as<std::string>());
    } catch (const std::runtime_error& e) {
      if (!root["head"]) throw;
      throw fail("head", e.what());
    }
    const YAML::Node names = req("class_names");
    if (names.IsSequence()) {
      c.class_names = names.as<std::vector<std::string>>();
    } else {  // a names file, one class per line (darknet's coco.names)
      const std::string file = resolve(names.as<std::string>());
      if (const std::string why = regularFileProblem(file, kMaxCalibrationFileBytes); !why.empty())
        throw fail("class_names", "file " + file + " cannot be read: " + why);
      std::ifstream f(file);
      if (!f) throw fail("class_names", "file " + file + " cannot be read");
      for (std::string line; std::getline(f, line);)
        if (!line.empty()) c.class_names.push_back(line);
    }
    if (c.class_names.empty()) throw fail("class_names", "is empty");
    if (root["score_threshold"]) c.score_threshold = root["score_threshold"].as<float>();
    if (root["nms_threshold"]) c.nms_threshold = root["nms_threshold"].as<float>();
    if (root["nms_across_classes"]) c.nms_across_classes = root["nms_across_classes"].as<bool>();
    if (!scoreThresholdOk(c.score_threshold))
      throw fail("score_threshold", "must be in (0, 1), got " + number(c.score_threshold));
    if (!nmsThresholdOk(c.nms_threshold)) throw fail("nms_threshold", "must be in (0, 1], got " + number(c.nms_threshold));
    if (root["moving_classes"]) c.moving_classes = root["moving_classes"].as<std::vector<std::string>>();
    if (root["persons_moving"] && root["persons_moving"].as<bool>()) c.moving_classes.push_back("person");
    for (const auto& m : c.moving_classes)
      if (std::find(c.class_names.begin(), c.class_names.end(), m) == c.class_names.end())
        throw fail("moving_classes", "names '" + m + "', which is not one of the model's classes");
    const auto scalar3 = [&](const char* key, cv::Scalar& out) {
      if (!root[key]) return;
      const auto v = root[key].as<std::vector<double>>();
      if (v.size() == 1) out = cv::Scalar::all(v[0]);
      else if (v.size() == 3) out = cv::Scalar(v[0], v[1], v[2]);
      else throw fail(key, "must have 1 or 3 values");
    };
    scalar3("mean", c.mean);
    scalar3("std", c.std);
    for (int k = 0; k < 3; ++k)
      if (!(c.std[k] > 0)) throw fail("std", "must be positive");
    if (root["swap_rb"]) c.swap_rb = root["swap_rb"].as<bool>();
    if (root["letterbox"]) c.letterbox = root["letterbox"].as<bool>();
    if (root["pad_value"]) c.pad_value = root["pad_value"].as<float>();
    if (root["strides"]) c.strides = root["strides"].as<std::vector<int>>();
    if (root["reg_max"]) c.reg_max = root["reg_max"].as<int>();
    if (root["center_offset"]) c.center_offset = root["center_offset"].as<float>();
    if (c.reg_max < 1) throw fail("reg_max", "must be >= 1");
    for (int s : c.strides)
      if (s <= 0) throw fail("strides", "must be positive");
  } catch (const YAML::Exception& e) {
    throw std::runtime_error("detector model config " + yaml_path + ": " + e.what());
  }
  return c;
}

DnnBackend parseDnnBackend(const std::string& s) {
  if (s == "opencv") return DnnBackend::OpenCv;
  if (s == "default") return DnnBackend::Default;
  throw std::invalid_argument("dnn_backend: must be 'opencv' or 'default', got '" + s + "'");
}

DnnTarget parseDnnTarget(const std::string& s) {
  if (s == "cpu") return DnnTarget::Cpu;
  if (s == "opencl") return DnnTarget::OpenCl;
  if (s == "opencl_fp16") return DnnTarget::OpenClFp16;
  throw std::invalid_argument("dnn_target: must be 'cpu', 'opencl' or 'opencl_fp16', got '" + s + "'");
}

std::string toString(DnnBackend b) {
  switch (b) {
    case DnnBackend::OpenCv: return "opencv";
    case DnnBackend::Default: return "default";
  }
  return "?";
}

std::string toString(DnnTarget t) {
  switch (t) {
    case DnnTarget::Cpu: return "cpu";
    case DnnTarget::OpenCl: return "opencl";
    case DnnTarget::OpenClFp16: return "opencl_fp16";
  }
  return "?";
}

const ParamTable<DetectorStageConfig>& DetectorStageConfig::params() {
  using C = DetectorStageConfig;
  using R = ParamRange;
  constexpr auto kRun = ParamChange::Runtime;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("detector");
    t.text("model_config", [](C& c) -> std::string& { return c.model_config; },
           "Path of a model YAML (config/detector/*.yaml); empty: no model (the stage reports ERROR)")
        .optionalNumber("score_threshold", [](C& c) -> std::optional<float>& { return c.score_threshold; },
                        R::strictlyBetween(0, 1), "Smallest class score kept", "the model YAML's", kRun)
        .optionalNumber("nms_threshold", [](C& c) -> std::optional<float>& { return c.nms_threshold; },
                        R::aboveUpTo(0, 1), "IoU above which a box is suppressed", "the model YAML's", kRun)
        .choice("dnn_backend", {"opencv", "default"}, [](const C& c) { return toString(c.dnn_backend); },
                [](C& c, const std::string& v) { c.dnn_backend = parseDnnBackend(v); }, "cv::dnn backend")
        .choice("dnn_target", {"cpu", "opencl", "opencl_fp16"}, [](const C& c) { return toString(c.dnn_target); },
                [](C& c, const std::string& v) { c.dnn_target = parseDnnTarget(v); }, "cv::dnn target")
        .flag("only_moving", [](C& c) -> bool& { return c.only_moving; },
              "Publish (and mask) the model's moving classes only", kRun)
        .flag("publish_annotated", [](C& c) -> bool& { return c.publish_annotated; },
              "Publish detections/image (the image with the boxes drawn)", kRun);
    return t;
  }();
  return t;
}

void DetectorStageConfig::validate() const { params().check(*this); }

DetectorStageConfig DetectorStageConfig::fromParams(const ParamSource& p, DetectorStageConfig base) {
  return params().read(p, std::move(base));
}

DnnDevice DetectorStageConfig::device() const { return DnnDevice{toString(dnn_backend), toString(dnn_target)}; }

DetectorModelConfig DetectorStageConfig::loadModel() const {
  if (model_config.empty())
    throw std::runtime_error("model_config (path of a model YAML, see config/detector/) is not set");
  validate();
  DetectorModelConfig c = loadDetectorConfig(model_config);
  if (score_threshold) c.score_threshold = *score_threshold;
  if (nms_threshold) c.nms_threshold = *nms_threshold;
  return c;
}

Letterbox Letterbox::compute(int iw, int ih, int nw, int nh, bool keep_aspect) {
  Letterbox lb;
  if (!keep_aspect) {
    lb.scale_x = float(nw) / iw;
    lb.scale_y = float(nh) / ih;
    return lb;
  }
  const float s = std::min(float(nw) / iw, float(nh) / ih);
  const int rw = std::max(1, int(std::lround(iw * s))), rh = std::max(1, int(std::lround(ih * s)));
  lb.scale_x = float(rw) / iw;
  lb.scale_y = float(rh) / ih;
  lb.pad_x = float((nw - rw) / 2);
  lb.pad_y = float((nh - rh) / 2);
  return lb;
}

cv::Mat makeInputBlob(const cv::Mat& image, const DetectorModelConfig& cfg, Letterbox* lb_out) {
  if (image.empty()) throw std::invalid_argument("detector: empty image");
  if (image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3 && image.channels() != 4))
    throw std::invalid_argument("detector: image must be 8-bit grey, BGR or BGRA (got type " +
                                std::to_string(image.type()) + ")");
  cv::Mat bgr;
  if (image.channels() == 1) cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
  else if (image.channels() == 4) cv::cvtColor(image, bgr, cv::COLOR_BGRA2BGR);
  else bgr = image;
  const Letterbox lb = Letterbox::compute(image.cols, image.rows, cfg.input_width, cfg.input_height, cfg.letterbox);
  const int rw = int(std::lround(image.cols * lb.scale_x)), rh = int(std::lround(image.rows * lb.scale_y));
  cv::Mat resized;
  cv::resize(bgr, resized, cv::Size(rw, rh), 0, 0, cv::INTER_LINEAR);
  cv::Mat input(cfg.input_height, cfg.input_width, CV_8UC3, cv::Scalar::all(cfg.pad_value));
  resized.copyTo(input(cv::Rect(int(lb.pad_x), int(lb.pad_y), rw, rh)));
  if (cfg.swap_rb) cv::cvtColor(input, input, cv::COLOR_BGR2RGB);
  cv::Mat f;
  input.convertTo(f, CV_32FC3);
  f -= cfg.mean;
  cv::divide(f, cfg.std, f);
  if (lb_out) *lb_out = lb;
  return cv::dnn::blobFromImage(f, 1.0, cv::Size(), cv::Scalar(), false, false, CV_32F);
}

namespace {

/// An output as a 2-D [rows, cols] float view (drops leading 1-sized dims).
cv::Mat as2d(const cv::Mat& m, const char* head) {
  if (m.type() != CV_32F) throw std::runtime_error(std::string(head) + " head: output is not float32");
  if (m.dims == 2) return m;
  int lead = 1;
  for (int d = 0; d < m.dims - 2; ++d) lead *= m.size[d];
  if (lead != 1 && m.dims == 3)
    throw std::runtime_error(std::string(head) + " head: batch size " + std::to_string(lead) + " not supported");
  const int rows = m.dims == 3 ? m.size[1] : int(m.total() / m.size[m.dims - 1]);
  return cv::Mat(rows, m.size[m.dims - 1], CV_32F, const_cast<uchar*>(m.ptr()));
}

void bestClass(const float* scores, int n, int* cls, float* score) {
  int best = 0;
  for (int k = 1; k < n; ++k)
    if (scores[k] > scores[best]) best = k;
  *cls = best;
  *score = scores[best];
}

std::string shapeOf(const cv::Mat& m) {
  std::string s = "[";
  for (int d = 0; d < m.dims; ++d) s += (d ? "x" : "") + std::to_string(m.size[d]);
  return s + "]";
}

}  // namespace

std::vector<Candidate> decodeDarknet(const std::vector<cv::Mat>& outs, const DetectorModelConfig& cfg) {
  const int nc = int(cfg.class_names.size());
  std::vector<Candidate> c;
  for (const auto& o : outs) {
    const cv::Mat m = as2d(o, "darknet");
    if (m.cols != 5 + nc)
      throw std::runtime_error("darknet head: output " + shapeOf(o) + " has " + std::to_string(m.cols) +
                               " columns, expected 5 + " + std::to_string(nc) + " classes");
    for (int r = 0; r < m.rows; ++r) {
      const float* p = m.ptr<float>(r);
      int cls;
      float score;
      bestClass(p + 5, nc, &cls, &score);  // already objectness * class probability
      if (score < cfg.score_threshold) continue;
      const float cx = p[0] * cfg.input_width, cy = p[1] * cfg.input_height;
      const float w = p[2] * cfg.input_width, h = p[3] * cfg.input_height;
      c.push_back({cls, score, cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2});
    }
  }
  return c;
}

std::vector<Candidate> decodeYoloV5(const std::vector<cv::Mat>& outs, const DetectorModelConfig& cfg) {
  const int nc = int(cfg.class_names.size());
  if (outs.size() != 1) throw std::runtime_error("yolov5 head: expected 1 output, got " + std::to_string(outs.size()));
  const cv::Mat m = as2d(outs[0], "yolov5");
  if (m.cols != 5 + nc)
    throw std::runtime_error("yolov5 head: output " + shapeOf(outs[0]) + " must be [1, N, 5 + " +
                             std::to_string(nc) + "]");
  std::vector<Candidate> c;
  for (int r = 0; r < m.rows; ++r) {
    const float* p = m.ptr<float>(r);
    if (p[4] < cfg.score_threshold) continue;
    int cls;
    float score;
    bestClass(p + 5, nc, &cls, &score);
    score *= p[4];
    if (score < cfg.score_threshold) continue;
    c.push_back({cls, score, p[0] - p[2] / 2, p[1] - p[3] / 2, p[0] + p[2] / 2, p[1] + p[3] / 2});
  }
  return c;
}

std::vector<Candidate> decodeYoloV8(const std::vector<cv::Mat>& outs, const DetectorModelConfig& cfg) {
  const int nc = int(cfg.class_names.size());
  if (outs.size() != 1) throw std::runtime_error("yolov8 head: expected 1 output, got " + std::to_string(outs.size()));
  cv::Mat m = as2d(outs[0], "yolov8");
  if (m.rows == 4 + nc && m.cols != 4 + nc) m = m.t();  // [4 + C, N] -> [N, 4 + C]
  if (m.cols != 4 + nc)
    throw std::runtime_error("yolov8 head: output " + shapeOf(outs[0]) + " must be [1, 4 + " +
                             std::to_string(nc) + ", N]");
  std::vector<Candidate> c;
  for (int r = 0; r < m.rows; ++r) {
    const float* p = m.ptr<float>(r);
    int cls;
    float score;
    bestClass(p + 4, nc, &cls, &score);
    if (score < cfg.score_threshold) continue;
    c.push_back({cls, score, p[0] - p[2] / 2, p[1] - p[3] / 2, p[0] + p[2] / 2, p[1] + p[3] / 2});
  }
  return c;
}

std::vector<Candidate> decodeNanoDet(const std::vector<cv::Mat>& outs, const DetectorModelConfig& cfg) {
  const int nc = int(cfg.class_names.size());
  const int bins = cfg.reg_max + 1, nreg = 4 * bins;
  struct Level {
    int stride, gw, gh;
    cv::Mat cls, reg;  // [N, nc] and [N, nreg] (views with a column offset for merged outputs)
  };
  std::vector<Level> levels;
  for (int s : cfg.strides)
    levels.push_back({s, (cfg.input_width + s - 1) / s, (cfg.input_height + s - 1) / s, {}, {}});
  std::vector<cv::Mat> mats;
  for (const auto& o : outs) mats.push_back(as2d(o, "nanodet"));
  if (mats.size() == 1 && mats[0].cols == nc + nreg) {
    // Merged output: levels stacked along N, scores then distance bins along the last axis.
    int row = 0;
    for (auto& l : levels) {
      const int n = l.gw * l.gh;
      if (row + n > mats[0].rows) break;
      l.cls = mats[0](cv::Range(row, row + n), cv::Range(0, nc));
      l.reg = mats[0](cv::Range(row, row + n), cv::Range(nc, nc + nreg));
      row += n;
    }
    if (row != mats[0].rows)
      throw std::runtime_error("nanodet head: merged output " + shapeOf(outs[0]) + " does not hold the grids of strides " +
                               "for input " + std::to_string(cfg.input_width) + "x" + std::to_string(cfg.input_height));
  } else {
    for (const auto& m : mats) {
      bool used = false;
      for (auto& l : levels) {
        if (m.rows != l.gw * l.gh) continue;
        if (m.cols == nc && l.cls.empty()) l.cls = m, used = true;
        else if (m.cols == nreg && l.reg.empty()) l.reg = m, used = true;
        if (used) break;
      }
      if (!used)
        throw std::runtime_error("nanodet head: output " + shapeOf(m) + " matches no stride's grid with " +
                                 std::to_string(nc) + " classes or " + std::to_string(nreg) + " distance bins");
    }
  }
  std::vector<Candidate> c;
  std::vector<float> prob(bins);
  for (const auto& l : levels) {
    if (l.cls.empty() || l.reg.empty())
      throw std::runtime_error("nanodet head: no scores or distances for stride " + std::to_string(l.stride));
    for (int i = 0; i < l.cls.rows; ++i) {
      int cls;
      float score;
      bestClass(l.cls.ptr<float>(i), nc, &cls, &score);
      if (score < cfg.score_threshold) continue;
      const float* d = l.reg.ptr<float>(i);
      float dist[4];
      for (int side = 0; side < 4; ++side) {  // softmax over the bins, then its expectation
        const float* b = d + side * bins;
        const float mx = *std::max_element(b, b + bins);
        float sum = 0.f, e = 0.f;
        for (int k = 0; k < bins; ++k) {
          prob[k] = std::exp(b[k] - mx);
          sum += prob[k];
          e += prob[k] * k;
        }
        dist[side] = e / sum * l.stride;
      }
      const float cx = (i % l.gw + cfg.center_offset) * l.stride;
      const float cy = (i / l.gw + cfg.center_offset) * l.stride;
      c.push_back({cls, score, cx - dist[0], cy - dist[1], cx + dist[2], cy + dist[3]});
    }
  }
  return c;
}

std::vector<Candidate> decodeHead(const std::vector<cv::Mat>& outs, const DetectorModelConfig& cfg) {
  switch (cfg.head) {
    case DetectorHead::Darknet: return decodeDarknet(outs, cfg);
    case DetectorHead::YoloV5: return decodeYoloV5(outs, cfg);
    case DetectorHead::YoloV8: return decodeYoloV8(outs, cfg);
    case DetectorHead::NanoDet: return decodeNanoDet(outs, cfg);
  }
  return {};
}

namespace {

// cv::dnn::NMSBoxes over the candidates `idx`; the survivors appended to `kept`.
void nmsInto(const std::vector<Candidate>& cands, const std::vector<int>& idx, float iou_threshold,
             std::vector<Candidate>& kept) {
  std::vector<cv::Rect2d> boxes;
  std::vector<float> scores;
  for (int i : idx) {
    const auto& c = cands[i];
    boxes.emplace_back(c.x_min, c.y_min, c.x_max - c.x_min, c.y_max - c.y_min);
    scores.push_back(c.score);
  }
  std::vector<int> keep;
  cv::dnn::NMSBoxes(boxes, scores, 0.f, iou_threshold, keep);
  for (int k : keep) kept.push_back(cands[idx[k]]);
}

std::vector<Candidate> byScore(std::vector<Candidate> kept) {
  std::sort(kept.begin(), kept.end(), [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
  return kept;
}

}  // namespace

std::vector<Candidate> nmsPerClass(const std::vector<Candidate>& cands, float iou_threshold) {
  std::map<int, std::vector<int>> by_class;
  for (int i = 0; i < int(cands.size()); ++i) by_class[cands[i].class_id].push_back(i);
  std::vector<Candidate> kept;
  for (const auto& [cls, idx] : by_class) nmsInto(cands, idx, iou_threshold, kept);
  return byScore(std::move(kept));
}

std::vector<Candidate> nmsAcrossClasses(const std::vector<Candidate>& cands, float iou_threshold) {
  std::vector<int> all(cands.size());
  for (int i = 0; i < int(cands.size()); ++i) all[i] = i;
  std::vector<Candidate> kept;
  nmsInto(cands, all, iou_threshold, kept);
  return byScore(std::move(kept));
}

float boxIoU(const Detection& a, const Detection& b) {
  const float ix = std::max(0.f, std::min(a.x_max, b.x_max) - std::max(a.x_min, b.x_min));
  const float iy = std::max(0.f, std::min(a.y_max, b.y_max) - std::max(a.y_min, b.y_min));
  const float inter = ix * iy;
  const float ua = (a.x_max - a.x_min) * (a.y_max - a.y_min) + (b.x_max - b.x_min) * (b.y_max - b.y_min) - inter;
  return ua > 0 ? inter / ua : 0.f;
}

std::vector<Detection> toDetections(const std::vector<Candidate>& cands, const Letterbox& lb,
                                    const DetectorModelConfig& cfg, int iw, int ih, bool only_moving) {
  std::vector<Detection> out;
  for (const auto& c : cands) {
    if (c.class_id < 0 || c.class_id >= int(cfg.class_names.size())) continue;
    const std::string& name = cfg.class_names[c.class_id];
    if (only_moving && std::find(cfg.moving_classes.begin(), cfg.moving_classes.end(), name) == cfg.moving_classes.end())
      continue;
    Detection d;
    d.class_id = c.class_id;
    d.class_name = name;
    d.score = c.score;
    d.x_min = std::clamp(lb.toImageX(c.x_min), 0.f, float(iw));
    d.y_min = std::clamp(lb.toImageY(c.y_min), 0.f, float(ih));
    d.x_max = std::clamp(lb.toImageX(c.x_max), 0.f, float(iw));
    d.y_max = std::clamp(lb.toImageY(c.y_max), 0.f, float(ih));
    if (d.x_max > d.x_min && d.y_max > d.y_min) out.push_back(d);
  }
  return out;
}

cv::Mat annotateDetections(const cv::Mat& image, const std::vector<Detection>& dets) {
  cv::Mat out;
  if (image.channels() == 1) cv::cvtColor(image, out, cv::COLOR_GRAY2BGR);
  else if (image.channels() == 4) cv::cvtColor(image, out, cv::COLOR_BGRA2BGR);
  else out = image.clone();
  for (const auto& d : dets) {
    const cv::Scalar colour = cv::Scalar(40 + (d.class_id * 67) % 200, 255 - (d.class_id * 41) % 180, (d.class_id * 97) % 255);
    cv::rectangle(out, cv::Point(int(d.x_min), int(d.y_min)), cv::Point(int(d.x_max), int(d.y_max)), colour, 2);
    char label[96];
    std::snprintf(label, sizeof(label), "%s %.2f", d.class_name.c_str(), d.score);
    int base = 0;
    const cv::Size ts = cv::getTextSize(label, cv::FONT_HERSHEY_SIMPLEX, 0.5, 1, &base);
    const cv::Point org(int(d.x_min), std::max(ts.height + 2, int(d.y_min) - 2));
    cv::rectangle(out, org + cv::Point(0, base), org + cv::Point(ts.width, -ts.height - 2), colour, cv::FILLED);
    cv::putText(out, label, org, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
  return out;
}

struct Detector::Impl {
  cv::dnn::Net net;
  std::vector<std::string> out_names;
};

Detector::Detector(const DetectorModelConfig& cfg, const DnnDevice& device) : cfg_(cfg), impl_(new Impl) {
  if (const std::string why = modelFileProblem(cfg.model_path); !why.empty())
    throw std::runtime_error("detector: model file " + cfg.model_path + " does not exist or cannot be read: " + why +
                             (cfg.format == ModelFormat::Onnx ? " (scripts/setup makes the NanoDet model)" : ""));
  if (cfg.format == ModelFormat::Darknet)
    if (const std::string why = modelFileProblem(cfg.darknet_cfg); !why.empty())
      throw std::runtime_error("detector: Darknet cfg " + cfg.darknet_cfg + " does not exist or cannot be read: " + why);
  try {
    impl_->net = cfg.format == ModelFormat::Onnx ? cv::dnn::readNetFromONNX(cfg.model_path)
                                                 : cv::dnn::readNetFromDarknet(cfg.darknet_cfg, cfg.model_path);
  } catch (const cv::Exception& e) {
    throw std::runtime_error("detector: cannot load model " + cfg.model_path + ": " + e.what());
  }
  if (impl_->net.empty()) throw std::runtime_error("detector: model " + cfg.model_path + " holds no network");
  int backend = cv::dnn::DNN_BACKEND_OPENCV, target = cv::dnn::DNN_TARGET_CPU;
  DnnBackend b = DnnBackend::OpenCv;
  DnnTarget t = DnnTarget::Cpu;
  try {
    b = parseDnnBackend(device.backend);
  } catch (const std::invalid_argument&) {
    throw std::runtime_error("detector: unknown dnn backend '" + device.backend + "' (opencv, default)");
  }
  try {
    t = parseDnnTarget(device.target);
  } catch (const std::invalid_argument&) {
    throw std::runtime_error("detector: unknown dnn target '" + device.target + "' (cpu, opencl, opencl_fp16)");
  }
  switch (b) {
    case DnnBackend::OpenCv: backend = cv::dnn::DNN_BACKEND_OPENCV; break;
    case DnnBackend::Default: backend = cv::dnn::DNN_BACKEND_DEFAULT; break;
  }
  switch (t) {
    case DnnTarget::Cpu: target = cv::dnn::DNN_TARGET_CPU; break;
    case DnnTarget::OpenCl: target = cv::dnn::DNN_TARGET_OPENCL; break;
    case DnnTarget::OpenClFp16: target = cv::dnn::DNN_TARGET_OPENCL_FP16; break;
  }
  impl_->net.setPreferableBackend(backend);
  impl_->net.setPreferableTarget(target);
  impl_->out_names = impl_->net.getUnconnectedOutLayersNames();
}

Detector::~Detector() = default;

void Detector::setThresholds(float score_threshold, float nms_threshold) {
  if (!scoreThresholdOk(score_threshold))
    throw std::invalid_argument("score_threshold: must be in (0, 1), got " + number(score_threshold));
  if (!nmsThresholdOk(nms_threshold))
    throw std::invalid_argument("nms_threshold: must be in (0, 1], got " + number(nms_threshold));
  cfg_.score_threshold = score_threshold;
  cfg_.nms_threshold = nms_threshold;
}

std::vector<Detection> Detector::detect(const cv::Mat& image, bool only_moving) {
  Letterbox lb;
  const cv::Mat blob = makeInputBlob(image, cfg_, &lb);
  try {
    impl_->net.setInput(blob);
    impl_->net.forward(outs_, impl_->out_names);
  } catch (const cv::Exception& e) {
    throw std::runtime_error("detector: inference failed on model " + cfg_.model_path + ": " + e.what());
  }
  const auto candidates = decodeHead(outs_, cfg_);
  const auto kept = cfg_.nms_across_classes ? nmsAcrossClasses(candidates, cfg_.nms_threshold)
                                            : nmsPerClass(candidates, cfg_.nms_threshold);
  return toDetections(kept, lb, cfg_, image.cols, image.rows, only_moving);
}

}  // namespace fisheye_mapping
