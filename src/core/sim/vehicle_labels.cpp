#include "fisheye_mapping/core/sim/vehicle_labels.h"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

namespace fisheye_mapping {
namespace synth {

std::vector<VisibleBox> visibleBoxes(const cv::Mat& ids, int num_ids, int min_pixels) {
  if (ids.type() != CV_16SC1) throw std::invalid_argument("visibleBoxes: the id image must be CV_16SC1");
  std::vector<int> x0(num_ids, ids.cols), y0(num_ids, ids.rows), x1(num_ids, -1), y1(num_ids, -1), n(num_ids, 0);
  for (int v = 0; v < ids.rows; ++v) {
    const int16_t* row = ids.ptr<int16_t>(v);
    for (int u = 0; u < ids.cols; ++u) {
      const int id = row[u];
      if (id < 0 || id >= num_ids) continue;
      x0[id] = std::min(x0[id], u), x1[id] = std::max(x1[id], u);
      y0[id] = std::min(y0[id], v), y1[id] = std::max(y1[id], v);
      ++n[id];
    }
  }
  std::vector<VisibleBox> out;
  for (int id = 0; id < num_ids; ++id) {
    if (n[id] == 0 || n[id] < min_pixels) continue;
    out.push_back({id, cv::Rect(x0[id], y0[id], x1[id] - x0[id] + 1, y1[id] - y0[id] + 1), n[id]});
  }
  return out;
}

std::string yoloLine(int class_id, const cv::Rect2d& box, const cv::Size& image) {
  // Corners rounded inwards to 1e-6 of the image, so that cx -+ w / 2 never
  // leaves [0, 1] by a rounding error (a strict reader would reject it).
  auto in = [](double lo, double hi, double size, double* c, double* w) {
    const double a = std::ceil(lo / size * 1e6 - 1e-6) / 1e6, b = std::floor(hi / size * 1e6 + 1e-6) / 1e6;
    *c = 0.5 * (a + b), *w = b - a;
  };
  double cx, cy, w, h;
  in(box.x, box.x + box.width, image.width, &cx, &w);
  in(box.y, box.y + box.height, image.height, &cy, &h);
  char buf[128];
  std::snprintf(buf, sizeof(buf), "%d %.7f %.7f %.6f %.6f", class_id, cx, cy, w, h);
  return buf;
}

void parseYoloLine(const std::string& line, const cv::Size& image, int* class_id, cv::Rect2d* box) {
  std::istringstream in(line);
  std::vector<std::string> fields;
  for (std::string f; in >> f;) fields.push_back(f);
  if (fields.size() != 5) {
    throw std::invalid_argument("YOLO label needs 5 fields (class cx cy w h), got " + std::to_string(fields.size()) +
                                " in '" + line + "'");
  }
  double v[5];
  for (int i = 0; i < 5; ++i) {
    size_t used = 0;
    try {
      v[i] = std::stod(fields[i], &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != fields[i].size()) throw std::invalid_argument("YOLO label field " + std::to_string(i + 1) + " is not a number: '" + fields[i] + "'");
    if (i > 0 && !(v[i] >= 0 && v[i] <= 1)) {
      throw std::invalid_argument("YOLO label field " + std::to_string(i + 1) + " must lie in [0, 1], got " + fields[i]);
    }
  }
  if (v[0] != static_cast<int>(v[0]) || v[0] < 0) throw std::invalid_argument("YOLO class must be a whole number >= 0, got " + fields[0]);
  *class_id = static_cast<int>(v[0]);
  const double w = v[3] * image.width, h = v[4] * image.height;
  *box = cv::Rect2d(v[1] * image.width - 0.5 * w, v[2] * image.height - 0.5 * h, w, h);
}

}  // namespace synth
}  // namespace fisheye_mapping
