#include "fisheye_mapping/core/sync/frame_pacer.h"

#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>

namespace fisheye_mapping {

FramePacer::FramePacer(const std::string& reference_topic, const std::vector<std::string>& image_topics,
                       int in_flight)
    : reference_(reference_topic), in_flight_(in_flight) {
  if (in_flight < 1 || in_flight > 16) {
    throw std::invalid_argument("frame sets in flight must be 1 to 16, got " + std::to_string(in_flight));
  }
  for (const auto& t : image_topics) {
    if (!last_.emplace(t, -std::numeric_limits<double>::infinity()).second) {
      throw std::invalid_argument("image topic '" + t + "' is listed twice");
    }
  }
  if (!last_.count(reference_)) {
    throw std::invalid_argument("the reference topic '" + reference_ + "' is not one of the image topics");
  }
}

FramePacer::Step FramePacer::next(const std::string& topic, double stamp) {
  Step step;
  auto it = last_.find(topic);
  if (it == last_.end()) return step;  // not an image: publish in bag order
  const double previous = it->second;
  if (stamp < previous) {
    char buf[256];
    std::snprintf(buf, sizeof(buf), "stamps go backwards on %s: %.6f after %.6f", topic.c_str(), stamp, previous);
    step.kind = Step::kStampsBackwards;
    step.error = buf;
    return step;
  }
  it->second = stamp;
  if (topic == reference_ && stamp > previous) {
    // The second set always waits for the first: the pipeline's first set
    // builds its rig and starts its workers, and a set that came while the
    // depth stage had not yet taken the first would replace it (newest wins).
    if (!open_.empty() && (static_cast<int>(open_.size()) >= in_flight_ || frames_ == 1)) {
      step.kind = Step::kWaitThenPublish;
      step.wait_for = open_.front();
      open_.pop_front();
    }
    open_.push_back(stamp);
    ++frames_;
  }
  return step;
}

}  // namespace fisheye_mapping
