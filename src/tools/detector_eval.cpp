// detector_eval: precision, recall and AP at IoU 0.5 of a detector model on
// YOLO-format folders (images/NAME.png, labels/NAME.txt with `class cx cy w h`
// normalised, classes.txt), and the detector's time per frame. The model is
// loaded as the detector nodelet loads it (DetectorStageConfig::loadModel) and
// runs through the same core Detector.
//
// Every labelled class counts as "vehicle", and so does every detection of the
// model's moving classes (what the nodelet publishes and the masking uses).
// Boxes shorter than --min-height pixels are ignored on both sides: a short
// labelled box is no miss, a detection matched to one is no false positive, and
// neither is an unmatched short detection. Detections are matched greedily by
// descending score to the unmatched labelled box of highest IoU >= --iou,
// counted boxes before ignored ones (scripts/finetune/metrics.py is the same rule).
// Precision and recall are at the model's score threshold; AP (all-point
// interpolated) ranks every detection down to --ap-threshold. --sweep-thresholds
// adds a line per listed threshold from the same run (the detector runs once, at
// the lowest score asked for: its greedy non-maximum suppression and the
// matching by descending score give every higher threshold exactly what a run
// at that threshold gives).
//
// Bad items (a label outside the image, an empty label file, an image of
// another size than the folder's first, a class id beyond classes.txt, a
// malformed line, an unreadable image) are named with file and line and skipped.
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "cli.h"
#include "fisheye_mapping/core/detection/detector.h"

namespace fm = fisheye_mapping;
namespace cli = fm::cli;
namespace fs = std::filesystem;

namespace {

const char* kUsage =
    "usage: detector_eval --config YAML [options] DIR [DIR...]\n"
    "  DIR                  YOLO-format folder: images/NAME.png, labels/NAME.txt, classes.txt\n"
    "  --config YAML        detector model (config/detector/*.yaml)\n"
    "  --min-height PX      boxes shorter than this are ignored on both sides (default 24)\n"
    "  --iou T              IoU for a match (default 0.5)\n"
    "  --score-threshold S  precision / recall at this score (default: the model YAML's)\n"
    "  --ap-threshold S     lowest score ranked for AP (default 0.05, at most the score threshold)\n"
    "  --sweep-thresholds LIST  also precision / recall at each of these comma-separated scores,\n"
    "                       one line each ('at score S: precision P recall R (TP . FP . FN .)'), same run\n"
    "  --max-images N       evenly spaced subset of N images (default: all)\n"
    "  --dnn-target T       cpu | opencl | opencl_fp16 (default cpu)\n";

constexpr double kEdgeTolerance = 1e-3;  // normalised overhang allowed for rounding

struct Box {
  float x0, y0, x1, y1;
  float height() const { return y1 - y0; }
};

struct Item {
  std::string image, label;
};

struct Options {
  std::string config;
  std::vector<std::string> dirs;
  double min_height = 24, iou = 0.5, ap_threshold = 0.05;
  std::optional<double> score_threshold;
  std::vector<double> sweep;
  long long max_images = 0;
  std::string dnn_target = "cpu";
};

// Problems found in the input, by kind, with the first few messages printed.
class Problems {
 public:
  void add(const std::string& kind, const std::string& msg) {
    if (++counts_[kind] <= 5) std::cerr << "detector_eval: skipped: " << msg << "\n";
  }
  std::string summary() const {
    std::string s;
    for (const auto& [k, n] : counts_) s += (s.empty() ? "" : ", ") + std::to_string(n) + " " + k;
    return s;
  }
  int total() const {
    int t = 0;
    for (const auto& kv : counts_) t += kv.second;
    return t;
  }

 private:
  std::map<std::string, int> counts_;
};

int countClasses(const std::string& dir) {
  std::ifstream f(dir + "/classes.txt");
  if (!f) throw cli::UsageError(dir + "/classes.txt: missing (one class name per line)");
  int n = 0;
  for (std::string line; std::getline(f, line);)
    if (line.find_first_not_of(" \t\r") != std::string::npos) ++n;
  if (n == 0) throw cli::UsageError(dir + "/classes.txt: no class names");
  return n;
}

std::vector<Item> listItems(const std::string& dir, Problems& problems) {
  for (const char* sub : {"images", "labels"})
    if (!fs::is_directory(dir + "/" + sub))
      throw cli::UsageError(dir + "/" + sub + ": missing (a YOLO folder holds images/, labels/ and classes.txt)");
  std::vector<Item> items;
  for (const auto& e : fs::directory_iterator(dir + "/images")) {
    std::string ext = e.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
    if (ext != ".png" && ext != ".jpg" && ext != ".jpeg" && ext != ".bmp" && ext != ".pgm") continue;
    const std::string label = dir + "/labels/" + e.path().stem().string() + ".txt";
    if (!fs::exists(label)) {
      problems.add("missing label file", label + ": missing for " + e.path().string());
      continue;
    }
    items.push_back({e.path().string(), label});
  }
  std::sort(items.begin(), items.end(), [](const Item& a, const Item& b) { return a.image < b.image; });
  return items;
}

// The boxes of a label file in pixels of a w x h image; nullopt (reported) for a bad file.
std::optional<std::vector<Box>> readLabels(const std::string& path, int num_classes, int w, int h,
                                           Problems& problems) {
  std::ifstream f(path);
  std::vector<Box> boxes;
  int n = 0;
  for (std::string line; std::getline(f, line);) {
    ++n;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const std::string where = path + ":" + std::to_string(n);
    std::istringstream s(line);
    long long cls;
    double cx, cy, bw, bh;
    std::string extra;
    if (!(s >> cls >> cx >> cy >> bw >> bh) || (s >> extra)) {
      problems.add("malformed line", where + ": '" + line + "' is not 'class cx cy w h'");
      return std::nullopt;
    }
    if (cls < 0 || cls >= num_classes) {
      problems.add("class id out of range", where + ": class id " + std::to_string(cls) +
                                                " is not in classes.txt (0.." + std::to_string(num_classes - 1) + ")");
      return std::nullopt;
    }
    if (!(bw > 0 && bh > 0)) {
      problems.add("empty box", where + ": width and height must be positive");
      return std::nullopt;
    }
    const double x0 = cx - bw / 2, y0 = cy - bh / 2, x1 = cx + bw / 2, y1 = cy + bh / 2;
    if (std::min(x0, y0) < -kEdgeTolerance || std::max(x1, y1) > 1 + kEdgeTolerance) {
      problems.add("box outside image", where + ": box x " + cli::numberText(x0) + ".." + cli::numberText(x1) +
                                            " y " + cli::numberText(y0) + ".." + cli::numberText(y1) +
                                            " leaves the image (0..1)");
      return std::nullopt;
    }
    boxes.push_back({float(std::max(0.0, x0) * w), float(std::max(0.0, y0) * h), float(std::min(1.0, x1) * w),
                     float(std::min(1.0, y1) * h)});
  }
  if (boxes.empty()) {
    problems.add("empty label file", path + ": no boxes");
    return std::nullopt;
  }
  return boxes;
}

float iou(const Box& a, const fm::Detection& d) {
  return fm::boxIoU(fm::Detection{-1, "", 0.f, a.x0, a.y0, a.x1, a.y1}, d);
}

struct Scored {
  float score;
  bool tp;
};

// Greedy matching of one image (see the header comment). Returns the counted detections.
std::vector<Scored> matchImage(std::vector<fm::Detection> dets, const std::vector<Box>& gts, const Options& o,
                               int* n_counted) {
  std::stable_sort(dets.begin(), dets.end(), [](const auto& a, const auto& b) { return a.score > b.score; });
  std::vector<bool> used(gts.size(), false);
  std::vector<Scored> out;
  *n_counted = 0;
  for (const auto& g : gts) *n_counted += g.height() >= o.min_height;
  for (const auto& d : dets) {
    int best = -1;
    bool best_counted = false;
    float best_iou = 0.f;
    for (size_t g = 0; g < gts.size(); ++g) {
      const float v = iou(gts[g], d);
      if (used[g] || v < o.iou) continue;
      const bool counted = gts[g].height() >= o.min_height;
      if (best < 0 || counted > best_counted || (counted == best_counted && v > best_iou))
        best = int(g), best_counted = counted, best_iou = v;
    }
    if (best >= 0) {
      used[best] = true;
      if (best_counted) out.push_back({d.score, true});
    } else if (d.y_max - d.y_min >= o.min_height) {
      out.push_back({d.score, false});
    }
  }
  return out;
}

double averagePrecision(std::vector<Scored> m, int n_gt) {
  if (n_gt == 0) return m.empty() ? 1.0 : 0.0;
  std::stable_sort(m.begin(), m.end(), [](const Scored& a, const Scored& b) { return a.score > b.score; });
  std::vector<double> rec{0.0}, prec{1.0};
  int tp = 0, fp = 0;
  for (const auto& s : m) {
    (s.tp ? tp : fp)++;
    rec.push_back(double(tp) / n_gt);
    prec.push_back(double(tp) / (tp + fp));
  }
  for (int i = int(prec.size()) - 2; i >= 0; --i) prec[i] = std::max(prec[i], prec[i + 1]);
  double ap = 0;
  for (size_t i = 1; i < rec.size(); ++i) ap += (rec[i] - rec[i - 1]) * prec[i];
  return ap;
}

Options parse(int argc, char** argv) {
  Options o;
  cli::forEachOption(argc, argv, 1, [&](const std::string& a, const cli::NextValue& next) {
    if (a == "--config") o.config = next();
    else if (a == "--min-height") o.min_height = cli::parseDouble(a, next(), 0, 1e5);
    else if (a == "--iou") o.iou = cli::parseDouble(a, next(), 0.01, 1);
    else if (a == "--score-threshold") o.score_threshold = cli::parseDouble(a, next(), 1e-4, 0.9999);
    else if (a == "--ap-threshold") o.ap_threshold = cli::parseDouble(a, next(), 1e-4, 0.9999);
    else if (a == "--sweep-thresholds") o.sweep = cli::parseDoubleList(a, next(), 1e-4, 0.9999);
    else if (a == "--max-images") o.max_images = cli::parseInt(a, next(), 1, 100000000);
    else if (a == "--dnn-target") o.dnn_target = next();
    else if (!a.empty() && a[0] != '-') o.dirs.push_back(a);
    else return false;
    return true;
  });
  if (o.config.empty()) throw cli::UsageError("--config is required");
  if (o.dirs.empty()) throw cli::UsageError("at least one YOLO-format folder is required");
  cli::requireInputFile("--config", o.config);
  try {
    fm::parseDnnTarget(o.dnn_target);
  } catch (const std::invalid_argument& e) {
    throw cli::UsageError(std::string("--dnn-target: ") + e.what());
  }
  for (const auto& d : o.dirs)
    if (!fs::is_directory(d)) throw cli::UsageError(d + ": no such folder");
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  const int rc = cli::parseCommandLine("detector_eval", kUsage, [&] { o = parse(argc, argv); });
  if (rc >= 0) return rc;
  try {
    Problems problems;
    std::vector<std::pair<Item, int>> items;  // with the folder's class count
    for (const auto& d : o.dirs) {
      const int nc = countClasses(d);
      for (auto& it : listItems(d, problems)) items.push_back({it, nc});
    }
    if (o.max_images > 0 && size_t(o.max_images) < items.size()) {
      std::vector<std::pair<Item, int>> sub;
      for (long long i = 0; i < o.max_images; ++i) sub.push_back(items[size_t(i * items.size() / o.max_images)]);
      items.swap(sub);
    }
    fm::DetectorStageConfig stage;
    stage.model_config = o.config;
    stage.dnn_target = fm::parseDnnTarget(o.dnn_target);
    fm::DetectorModelConfig model = stage.loadModel();
    const double operating = o.score_threshold.value_or(model.score_threshold);
    double lowest = std::min(operating, o.ap_threshold);
    for (double t : o.sweep) lowest = std::min(lowest, t);
    model.score_threshold = float(lowest);
    fm::Detector det(model, stage.device());

    std::vector<Scored> all;
    std::vector<double> ms;
    int n_gt = 0, n_ignored = 0, used = 0;
    cv::Size size;
    for (const auto& [it, nc] : items) {
      const cv::Mat img = cv::imread(it.image, cv::IMREAD_UNCHANGED);
      if (img.empty()) {
        problems.add("unreadable image", it.image + ": cannot be read as an image");
        continue;
      }
      if (size.empty()) size = img.size();
      if (img.size() != size) {
        problems.add("wrong image size", it.image + ": " + std::to_string(img.cols) + "x" + std::to_string(img.rows) +
                                             ", expected " + std::to_string(size.width) + "x" +
                                             std::to_string(size.height) + " (the first image's)");
        continue;
      }
      const auto gts = readLabels(it.label, nc, img.cols, img.rows, problems);
      if (!gts) continue;
      const auto t0 = std::chrono::steady_clock::now();
      const auto dets = det.detect(img, true);
      ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      int counted = 0;
      for (const auto& s : matchImage(dets, *gts, o, &counted)) all.push_back(s);
      n_gt += counted;
      n_ignored += int(gts->size()) - counted;
      ++used;
    }
    if (used == 0) {
      std::cerr << "detector_eval: no usable images" << (problems.total() ? " (skipped: " + problems.summary() + ")" : "")
                << "\n";
      return 1;
    }
    // TP and FP at score >= t; precision 1 with no detection, recall 1 with no vehicle.
    const auto countAt = [&](double t, int* tp, int* fp) {
      *tp = *fp = 0;
      for (const auto& s : all)
        if (s.score >= t) (s.tp ? *tp : *fp)++;
    };
    int tp = 0, fp = 0;
    countAt(operating, &tp, &fp);
    const double precision = tp + fp ? double(tp) / (tp + fp) : 1.0;
    const double recall = n_gt ? double(tp) / n_gt : 1.0;
    std::printf("model %s (%s, input %dx%d, classes counted as vehicle: %zu moving)\n", o.config.c_str(),
                fm::headName(model.head), model.input_width, model.input_height, model.moving_classes.size());
    std::printf("images %d", used);
    if (problems.total()) std::printf(" (skipped %d: %s)", problems.total(), problems.summary().c_str());
    std::printf("\nvehicles >= %g px tall: %d (shorter, ignored: %d)\n", o.min_height, n_gt, n_ignored);
    // AP ranks what a run without --sweep-thresholds ranks.
    std::vector<Scored> ranked;
    for (const auto& s : all)
      if (s.score >= float(std::min(operating, o.ap_threshold))) ranked.push_back(s);
    std::printf("precision %.3f recall %.3f AP50 %.3f (TP %d FP %d FN %d) at score >= %.2f, IoU %.2f\n", precision,
                recall, averagePrecision(ranked, n_gt), tp, fp, n_gt - tp, operating, o.iou);
    for (double t : o.sweep) {
      int stp = 0, sfp = 0;
      countAt(t, &stp, &sfp);
      std::printf("at score %.2f: precision %.3f recall %.3f (TP %d FP %d FN %d)\n", t,
                  stp + sfp ? double(stp) / (stp + sfp) : 1.0, n_gt ? double(stp) / n_gt : 1.0, stp, sfp, n_gt - stp);
    }
    // The first frame includes cv::dnn's lazy setup: timed apart.
    std::vector<double> rest(ms.begin() + (ms.size() > 1), ms.end());
    double mean = 0;
    for (double v : rest) mean += v / rest.size();
    std::nth_element(rest.begin(), rest.begin() + rest.size() / 2, rest.end());
    std::printf("time per frame %.1f ms (median %.1f, %zu frames; first frame %.1f ms)\n", mean,
                rest[rest.size() / 2], rest.size(), ms[0]);
    return 0;
  } catch (const cli::UsageError& e) {
    std::cerr << "detector_eval: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "detector_eval: " << e.what() << "\n";
    return 1;
  }
}
