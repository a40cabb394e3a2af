#include "fisheye_mapping/core/sync/frame_sync.h"

#include <sstream>

#include "fisheye_mapping/core/common/param_table.h"

namespace fisheye_mapping {

const ParamTable<FrameSyncConfig>& FrameSyncConfig::params() {
  using C = FrameSyncConfig;
  using R = ParamRange;
  constexpr auto kRun = ParamChange::Runtime;
  static const ParamTable<C> t = [] {
    ParamTable<C> t("sync");
    t.choice("policy", {"exact", "approximate"}, [](const C& c) { return toString(c.policy); },
             [](C& c, const std::string& v) { c.policy = parseSyncPolicy(v); },
             "exact (images with equal stamps) or approximate (stamps within max_interval); a change rebuilds the sync",
             kRun)
        .number("max_interval", [](C& c) -> double& { return c.max_interval; }, R::atLeast(0), "s",
                "Largest stamp spread within a set, approximate policy", kRun)
        .number("queue_size", [](C& c) -> int& { return c.queue_size; }, R::atLeast(1), "",
                "Open sets kept before the oldest is dropped", kRun)
        .number("silent_warning", [](C& c) -> double& { return c.silent_warning; }, R::above(0), "s",
                "Time without an image before a camera is reported (ERROR)", kRun)
        .number("time_reset_threshold", [](C& c) -> double& { return c.time_reset_threshold; }, R::atLeast(0), "s",
                "Time a camera may step back before the sync resets; 0: never", kRun)
        .names("image_topics", [](C& c) -> std::vector<std::string>& { return c.image_topics; },
               "One image topic per camera, in camera order; empty: the camchain's rostopics");
    t.rule([](const C& c) {
      for (size_t i = 0; i < c.image_topics.size(); ++i)
        if (c.image_topics[i].empty())
          throw std::invalid_argument("image_topics: topic " + std::to_string(i) + " is empty");
    });
    return t;
  }();
  return t;
}

void FrameSyncConfig::validate() const { params().check(*this); }

FrameSyncConfig FrameSyncConfig::fromParams(const ParamSource& p) { return params().read(p, FrameSyncConfig()); }

FrameSyncConfig FrameSyncConfig::fromParams(const ParamSource& p, FrameSyncConfig base) {
  return params().read(p, std::move(base));
}

}  // namespace fisheye_mapping
