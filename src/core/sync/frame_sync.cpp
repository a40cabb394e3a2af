#include "fisheye_mapping/core/sync/frame_sync.h"

#include <sstream>

#include "fisheye_mapping/core/common/params.h"

namespace fisheye_mapping {

void FrameSyncConfig::validate() const {
  if (toString(policy) == "?")
    throw std::invalid_argument("policy: not a sync policy (" + std::to_string(static_cast<int>(policy)) + ")");
  requireField(std::isfinite(max_interval) && max_interval >= 0, "max_interval", "must be >= 0 seconds", max_interval);
  requireField(queue_size >= 1, "queue_size", "must be at least 1", queue_size);
  requireField(std::isfinite(silent_warning) && silent_warning > 0, "silent_warning", "must be positive seconds",
          silent_warning);
  requireField(!std::isnan(time_reset_threshold), "time_reset_threshold", "must be a number of seconds (<= 0: never)",
          time_reset_threshold);
  for (size_t i = 0; i < image_topics.size(); ++i) {
    if (image_topics[i].empty())
      throw std::invalid_argument("image_topics: topic " + std::to_string(i) + " is empty");
  }
}

FrameSyncConfig FrameSyncConfig::fromParams(const ParamSource& p) {
  FrameSyncConfig c;
  if (std::string v; p.get("policy", v)) c.policy = parseSyncPolicy(v);
  p.get("max_interval", c.max_interval);
  p.get("queue_size", c.queue_size);
  p.get("silent_warning", c.silent_warning);
  p.get("time_reset_threshold", c.time_reset_threshold);
  p.get("image_topics", c.image_topics);
  c.validate();
  return c;
}

}  // namespace fisheye_mapping
