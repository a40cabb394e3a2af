#include "fisheye_mapping/core/detection/held_depth.h"

#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>
#include <string>

#include "fisheye_mapping/core/detection/depth_mask.h"
#include "fisheye_mapping/core/detection/mask_decisions.h"

namespace fisheye_mapping {

VehicleDepthHold::VehicleDepthHold(double hold_time_s) : hold_time_(hold_time_s) {
  if (!(hold_time_s >= 0.0) || !std::isfinite(hold_time_s))
    throw std::invalid_argument("hold_time must be >= 0 s, got " + std::to_string(hold_time_s));
}

void VehicleDepthHold::reset() {
  frames_.clear();
  decided_.clear();
  any_ = false;
}

std::size_t VehicleDepthHold::heldPixels() const {
  std::size_t n = 0;
  for (const Held& f : frames_) {
    for (const auto& t : f.tracks) n += t.second.size();
  }
  return n;
}

std::vector<VehicleDepthHold::Frame> VehicleDepthHold::update(
    std::int64_t stamp_ns, const cv::Mat& depth, const std::vector<Detection>& boxes,
    const std::vector<VehicleMotionTracker::Decision>& decisions, float margin_px, int image_w, int image_h) {
  if (depth.type() != CV_32FC1) throw std::invalid_argument("VehicleDepthHold: depth must be 32FC1");
  if (image_w <= 0 || image_h <= 0) throw std::invalid_argument("VehicleDepthHold: image size must be positive");
  if (decisions.size() != boxes.size())
    throw std::invalid_argument("VehicleDepthHold: " + std::to_string(decisions.size()) + " decisions for " +
                                std::to_string(boxes.size()) + " boxes");
  if (any_ && stamp_ns < last_stamp_ns_) reset();
  any_ = true;
  last_stamp_ns_ = stamp_ns;
  const std::int64_t hold_ns = std::llround(hold_time_ * 1e9);
  while (!frames_.empty() && stamp_ns - frames_.front().stamp_ns > hold_ns) frames_.pop_front();
  for (auto it = decided_.begin(); it != decided_.end();) {
    it = stamp_ns - it->second > hold_ns ? decided_.erase(it) : std::next(it);
  }

  // The vehicles decided in this frame set: parked ones release what they
  // held, moving ones drop it; neither is held again.
  std::set<int> release;
  for (const auto& d : decisions) {
    if (d.track < 0) continue;
    if (d.motion != VehicleMotion::Undecided) {
      const bool first = decided_.find(d.track) == decided_.end();
      decided_[d.track] = stamp_ns;
      if (first && d.motion == VehicleMotion::Parked) release.insert(d.track);
      if (first && d.motion == VehicleMotion::Moving) {
        for (Held& f : frames_) f.tracks.erase(d.track);
      }
    } else if (decided_.count(d.track)) {
      decided_[d.track] = stamp_ns;
    }
  }
  std::vector<Frame> out;
  if (!release.empty()) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (Held& f : frames_) {
      cv::Mat img;
      for (int t : release) {
        auto it = f.tracks.find(t);
        if (it == f.tracks.end()) continue;
        if (img.empty()) img = cv::Mat(f.size, CV_32FC1, cv::Scalar(nan));
        float* p = img.ptr<float>();
        for (const auto& [index, range] : it->second) p[index] = range;
        released_pixels_ += it->second.size();
        f.tracks.erase(it);
      }
      if (!img.empty()) {
        out.push_back({f.stamp_ns, img});
        ++released_frames_;
      }
    }
  }
  if (hold_time_ <= 0.0) return out;

  // This frame set's held depth: each undecided tracked vehicle's masked
  // pixels that no other masked box covers.
  Held held;
  held.stamp_ns = stamp_ns;
  held.size = depth.size();
  cv::Mat owner(depth.size(), CV_32SC1, cv::Scalar(-1));  // the held track; -2: another masked box
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    if (!masksVehicle(decisions[i].motion, false)) continue;
    const cv::Rect r = maskedRect(boxes[i], margin_px, depth.size(), image_w, image_h);
    if (r.empty()) continue;
    const int t = decisions[i].track;
    const bool hold = decisions[i].motion == VehicleMotion::Undecided && t >= 0 && !decided_.count(t);
    for (int v = r.y; v < r.y + r.height; ++v) {
      int* o = owner.ptr<int>(v);
      for (int u = r.x; u < r.x + r.width; ++u) {
        if (!hold) {
          o[u] = -2;
        } else if (o[u] == -1) {
          o[u] = t;
        } else if (o[u] != t) {
          o[u] = -2;  // two vehicles' boxes: neither's alone
        }
      }
    }
  }
  for (int v = 0; v < depth.rows; ++v) {
    const int* o = owner.ptr<int>(v);
    const float* d = depth.ptr<float>(v);
    for (int u = 0; u < depth.cols; ++u) {
      if (o[u] >= 0 && std::isfinite(d[u])) held.tracks[o[u]].emplace_back(v * depth.cols + u, d[u]);
    }
  }
  if (!held.tracks.empty()) frames_.push_back(std::move(held));
  return out;
}

}  // namespace fisheye_mapping
