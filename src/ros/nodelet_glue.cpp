#include "fisheye_mapping/ros/nodelet_glue.h"

#include <atomic>
#include <cstdio>
#include <utility>

#include "fisheye_mapping/ros/stage_health.h"

namespace fisheye_mapping {

namespace {

// One rosconsole location per (logger, level) for the process: rosconsole
// keeps pointers to registered locations, so they are never freed.
ros::console::LogLocation* logLocation(const std::string& logger, ros::console::Level level) {
  static std::mutex mutex;
  static std::map<std::pair<std::string, int>, ros::console::LogLocation*> locations;
  std::lock_guard<std::mutex> lock(mutex);
  ros::console::LogLocation*& loc = locations[{logger, int(level)}];
  if (!loc) {
    loc = new ros::console::LogLocation{false, false, ros::console::levels::Count, nullptr};
    ros::console::initializeLogLocation(loc, logger, level);
  }
  if (loc->level_ != level) {
    ros::console::setLogLocationLevel(loc, level);
    ros::console::checkLogLocationEnabled(loc);
  }
  return loc;
}

}  // namespace

NodeletLogger::NodeletLogger(std::string nodelet_name) : name_(std::move(nodelet_name)) {}

void NodeletLogger::log(ros::console::Level level, const std::string& text) const {
  ROSCONSOLE_AUTOINIT;
  const std::string logger = name_.empty() ? std::string(ROSCONSOLE_NAME_PREFIX)
                                           : std::string(ROSCONSOLE_NAME_PREFIX) + "." + name_;
  ros::console::LogLocation* loc = logLocation(logger, level);
  if (loc->logger_enabled_)
    ros::console::print(nullptr, loc->logger_, loc->level_, __FILE__, __LINE__, __func__, "%s", text.c_str());
}

void NodeletLogger::say(bool error, const std::string& text) const {
  if (!ros::ok()) {
    std::fprintf(stderr, "[%s] [%s]: %s\n", error ? "ERROR" : " INFO", name_.c_str(), text.c_str());
  } else {
    log(error ? ros::console::levels::Error : ros::console::levels::Info, text);
  }
}

void NodeletLogger::throttled(ros::console::Level level, double period_s, const std::string& key,
                              const std::string& text) {
  const double now = ros::Time::now().toSec();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = last_.find(key);
    // As ROSCONSOLE_THROTTLE_CHECK: a clock gone back lets the message through.
    if (it != last_.end() && now >= it->second && now < it->second + period_s) return;
    last_[key] = now;
  }
  log(level, text);
}

namespace {
std::atomic<FaultHook> fault_hook{nullptr};
}  // namespace

void setFaultHook(FaultHook hook) { fault_hook.store(hook); }

void faultPoint(const char* site) {
  if (FaultHook hook = fault_hook.load(std::memory_order_acquire)) hook(site);
}

void noteCallbackError(StageMonitor& monitor, NodeletLogger& log, const std::string& what, const ros::Time& stamp,
                       const std::string& why, double throttle_s) {
  const std::string at = what + " at " + formatStamp(std::int64_t(stamp.toNSec()));
  monitor.error(at + ": " + why);
  log.throttled(ros::console::levels::Error, throttle_s, "callback error: " + what, at + " skipped: " + why);
}

LazySubscription::LazySubscription(StageMonitor& monitor, NodeletLogger& log, std::string what,
                                   std::function<bool()> wanted, std::function<void()> subscribe,
                                   std::function<void()> unsubscribe)
    : monitor_(monitor),
      log_(log),
      what_(std::move(what)),
      wanted_(std::move(wanted)),
      subscribe_(std::move(subscribe)),
      unsubscribe_(std::move(unsubscribe)) {}

void LazySubscription::update() {
  std::lock_guard<std::mutex> lock(mutex_);
  const bool wanted = wanted_();
  try {
    if (wanted && !active_) {
      active_ = true;
      subscribe_();
    } else if (!wanted && active_) {
      active_ = false;
      unsubscribe_();
    }
  } catch (const std::exception& e) {
    monitor_.error("subscribing " + what_ + ": " + e.what());
    log_.error("cannot subscribe " + what_ + ": " + e.what());
    active_ = false;
    try {
      unsubscribe_();
    } catch (...) {
    }
  }
  monitor_.setInputExpected(wanted);
}

bool LazySubscription::active() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return active_;
}

ros::SubscriberStatusCallback LazySubscription::rosCallback() {
  return [this](const ros::SingleSubscriberPublisher&) { update(); };
}

image_transport::SubscriberStatusCallback LazySubscription::imageCallback() {
  return [this](const image_transport::SingleSubscriberPublisher&) { update(); };
}

ros::WallTimer simClockTimer(ros::NodeHandle& nh, std::function<void(std::int64_t)> f, double period_s) {
  return nh.createWallTimer(ros::WallDuration(period_s), [f = std::move(f)](const ros::WallTimerEvent&) {
    if (const std::int64_t now = simClockNs()) f(now);
  });
}

std::string describeTimeReset(std::int64_t from_ns, std::int64_t to_ns, const std::string& reason,
                              const std::string& stream) {
  return (stream.empty() ? "" : stream + " ") + formatStamp(from_ns) + " s -> " + formatStamp(to_ns) + " s: " + reason;
}

StageTimeline::StageTimeline(StageMonitor& monitor, NodeletLogger& log, std::string stage,
                             std::vector<std::string> streams, double threshold_s, OnReset on_reset)
    : monitor_(monitor),
      log_(log),
      stage_(std::move(stage)),
      streams_(std::move(streams)),
      timeline_(int(streams_.size()), threshold_s),
      on_reset_(std::move(on_reset)) {}

bool StageTimeline::observe(int stream, const ros::Time& stamp) {
  const StreamTimeline::Event ev = timeline_.observe(stream, std::int64_t(stamp.toNSec()));
  if (ev.kind == StreamTimeline::Kind::kStale) {
    monitor_.dropped("stale (old timeline)");
    return false;
  }
  if (ev.kind == StreamTimeline::Kind::kReset) reset(ev, streams_[std::size_t(stream)]);
  return true;
}

void StageTimeline::clock(std::int64_t now_ns, const std::string& clock_name) {
  if (auto ev = timeline_.clock(now_ns)) reset(*ev, clock_name);
}

void StageTimeline::setThreshold(double threshold_s) { timeline_ = StreamTimeline(int(streams_.size()), threshold_s); }

void StageTimeline::reset(const StreamTimeline::Event& ev, const std::string& stream) {
  const std::string done = on_reset_ ? on_reset_(ev, stream) : std::string();
  noteTimeReset(monitor_, log_, stage_, ev.from_ns, ev.to_ns, ev.reason, stream, done);
}

void noteTimeReset(StageMonitor& monitor, const NodeletLogger& log, const std::string& stage, std::int64_t from_ns,
                   std::int64_t to_ns, const std::string& reason, const std::string& stream, const std::string& done) {
  log.warn(stage + ": time went backwards" + (stream.empty() ? "" : " (" + stream + ")") + " from " +
            formatStamp(from_ns) + " s to " + formatStamp(to_ns) + " s (" + reason + ")" +
            (done.empty() ? "" : "; " + done));
  monitor.timeReset(describeTimeReset(from_ns, to_ns, reason, stream));
}

}  // namespace fisheye_mapping
