// The ROS glue every stage nodelet repeats, written once (library
// fisheye_mapping_ros). What it holds is how a stage meets ROS, never what
// the stage computes:
//   NodeletLogger      rosconsole under the nodelet's logger name (what the
//                      NODELET_* macros use), callable from shared code, with
//                      per-key throttling;
//   guarded()          runs a callback body; an exception is counted on the
//                      StageMonitor naming the callback and the stamp, logged
//                      (throttled), and the stage goes on;
//   LazySubscription   subscribe while someone listens to an output (the
//                      connect callbacks of image_pipeline's nodelets);
//   StageTimeline      time going backwards on the stage's input streams (a
//                      core StreamTimeline) and the sim clock polled on a wall
//                      timer: each reset logged and counted on the monitor;
//   checkedReconfigure a dynamic_reconfigure request checked against the
//                      stage's declarations, a refused one reported back;
//   faultPoint()       a seam where tests make a callback throw (the throwing
//                      hook is compiled in tests only: test_fault_injection_node).
// In a nodelet:
//   log_ = NodeletLogger(getName());
//   sub_ = std::make_unique<LazySubscription>(*monitor_, log_, "the frame sets",
//       [this] { return pub_.getNumSubscribers() > 0; },
//       [this] { sub_in_ = nh.subscribe(...); }, [this] { sub_in_.shutdown(); });
//   pub_ = nh.advertise<T>("out", 1, sub_->rosCallback(), sub_->rosCallback());
//   sub_->update();
//   guarded(*monitor_, log_, "depth", msg->header.stamp, [&] { ... });
#ifndef FISHEYE_MAPPING_ROS_NODELET_GLUE_H_
#define FISHEYE_MAPPING_ROS_NODELET_GLUE_H_

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <image_transport/single_subscriber_publisher.h>
#include <ros/console.h>
#include <ros/ros.h>

#include "fisheye_mapping/core/common/param_table.h"
#include "fisheye_mapping/core/common/stream_timeline.h"
#include "fisheye_mapping/ros/ros_params.h"
#include "fisheye_mapping/ros/stage_monitor.h"

namespace fisheye_mapping {

/// rosconsole under a nodelet's logger ("ros.fisheye_mapping.<name>", as
/// NODELET_INFO etc. with getName()), from code shared by every nodelet: the
/// log location is kept per logger and level, not per call site, so two
/// nodelets in one manager keep their own names. Thread-safe.
class NodeletLogger {
 public:
  explicit NodeletLogger(std::string nodelet_name = "");
  NodeletLogger(const NodeletLogger& o) : name_(o.name_) {}
  NodeletLogger& operator=(const NodeletLogger& o) {
    name_ = o.name_;
    return *this;
  }

  void log(ros::console::Level level, const std::string& text) const;
  void info(const std::string& text) const { log(ros::console::levels::Info, text); }
  void warn(const std::string& text) const { log(ros::console::levels::Warn, text); }
  void error(const std::string& text) const { log(ros::console::levels::Error, text); }
  /// error() or info(); once roscpp has shut down (a save on shutdown), on
  /// stderr as "[ERROR] [<name>]: <text>".
  void say(bool error, const std::string& text) const;
  /// At most once per `period_s` of ROS time (NODELET_*_THROTTLE's clock) for
  /// each `key` of this logger.
  void throttled(ros::console::Level level, double period_s, const std::string& key, const std::string& text);

  const std::string& name() const { return name_; }

 private:
  std::string name_;
  std::mutex mutex_;
  std::map<std::string, double> last_;  // key -> ROS time of its last message
};

/// Runs f(). An exception is caught: counted on `monitor` as
/// "<what> at <stamp>: <why>", logged (ERROR, at most once per `throttle_s`
/// for this `what`) as "<what> at <stamp> skipped: <why>", and false is
/// returned; the stage goes on.
template <class F>
bool guarded(StageMonitor& monitor, NodeletLogger& log, const std::string& what, const ros::Time& stamp, F&& f,
             double throttle_s = 1.0);
/// The part of guarded() after a catch (also for a callback that catches itself).
void noteCallbackError(StageMonitor& monitor, NodeletLogger& log, const std::string& what, const ros::Time& stamp,
                       const std::string& why, double throttle_s = 1.0);

/// A test seam. The stages call faultPoint("<stage> <callback>") inside the
/// callbacks whose exceptions must be caught, counted and survived (the depth
/// sweep, the TSDF fusion and its timers). Without a hook it does nothing but
/// read one pointer; a hook installed by a test (setFaultHook, from code
/// compiled in tests only) may throw there, as a bug or std::bad_alloc
/// would. Every nodelet loaded in the process sees the same hook.
using FaultHook = void (*)(const char* site);
void setFaultHook(FaultHook hook);
void faultPoint(const char* site);

/// Subscribes the stage's inputs while someone listens to its outputs, as
/// image_pipeline's nodelets do. update() asks `wanted`, then subscribes or
/// unsubscribes when the answer changed, and tells the monitor whether input
/// is expected (silence is not a stall while nobody listens). A subscription
/// that throws (an image_transport plugin that is not installed) is undone,
/// counted on the monitor ("subscribing <what>: ...") and logged; the next
/// update() tries again. Thread-safe; the callbacks run under its lock.
class LazySubscription {
 public:
  LazySubscription(StageMonitor& monitor, NodeletLogger& log, std::string what, std::function<bool()> wanted,
                   std::function<void()> subscribe, std::function<void()> unsubscribe);
  void update();
  bool active() const;
  /// Connect / disconnect callbacks that call update(), for advertise().
  ros::SubscriberStatusCallback rosCallback();
  image_transport::SubscriberStatusCallback imageCallback();

 private:
  StageMonitor& monitor_;
  NodeletLogger& log_;
  std::string what_;
  std::function<bool()> wanted_;
  std::function<void()> subscribe_, unsubscribe_;
  mutable std::mutex mutex_;
  bool active_ = false;
};

/// A wall timer (it runs while a bag's clock is paused) that calls
/// f(ROS time in ns) every `period_s` under sim time once a clock has come
/// (simClockNs() != 0), for the stages' clock-went-back checks.
ros::WallTimer simClockTimer(ros::NodeHandle& nh, std::function<void(std::int64_t)> f, double period_s = 0.2);

/// "<from> s -> <to> s: <reason>": a time reset as the diagnostics show it
/// ("last time reset"), behind "<stream> " when a stream is named.
std::string describeTimeReset(std::int64_t from_ns, std::int64_t to_ns, const std::string& reason,
                              const std::string& stream = "");

/// A time reset logged (WARN: "<stage>: time went backwards [(<stream>)] from
/// A s to B s (<reason>)[; <done>]") and counted on the monitor
/// (describeTimeReset), for resets a core unit found itself (the frame sync's).
void noteTimeReset(StageMonitor& monitor, const NodeletLogger& log, const std::string& stage, std::int64_t from_ns,
                   std::int64_t to_ns, const std::string& reason, const std::string& stream = "",
                   const std::string& done = "");

/// A stage's time resets: a core StreamTimeline over its input streams
/// (`streams` names them for the logs; "" for a stage of one stream), its
/// threshold the stage's time_reset_threshold (s; <= 0: never). On a reset
/// the stage's `on_reset` clears its time state and returns what it did (for
/// the log); the reset is then noted (noteTimeReset). Not thread-safe: the caller serialises
/// observe(), clock() and setThreshold() (its on_reset runs inside them).
class StageTimeline {
 public:
  using OnReset = std::function<std::string(const StreamTimeline::Event&, const std::string& stream)>;
  StageTimeline(StageMonitor& monitor, NodeletLogger& log, std::string stage, std::vector<std::string> streams,
                double threshold_s, OnReset on_reset = {});

  /// The stamp on its stream's timeline; false: a straggler of an old
  /// timeline, counted as dropped "stale (old timeline)" (drop it).
  bool observe(int stream, const ros::Time& stamp);
  /// The clock now (simClockTimer's value): a reset, named `clock_name`,
  /// when the newest stamp is ahead of it by more than the threshold.
  void clock(std::int64_t now_ns, const std::string& clock_name = "");
  /// A new threshold: the timeline starts afresh (its stamps are forgotten).
  void setThreshold(double threshold_s);

  const StreamTimeline& timeline() const { return timeline_; }

 private:
  void reset(const StreamTimeline::Event& ev, const std::string& stream);

  StageMonitor& monitor_;
  NodeletLogger& log_;
  std::string stage_;
  std::vector<std::string> streams_;
  StreamTimeline timeline_;
  OnReset on_reset_;
};

/// A dynamic_reconfigure request (`Cfg`, the generated class) checked against
/// the run-time declarations of `table` over `running`. Returns the new
/// config; or, for a value outside its declared range or choices, nullopt
/// after writing the running values back into the request (the caller sees
/// them), counting "<what> refused: <error>" on the monitor and logging it.
template <class C, class Cfg>
std::optional<C> checkedReconfigure(Cfg& request, const ParamTable<C>& table, const C& running, StageMonitor& monitor,
                                    const NodeletLogger& log, const std::string& what) {
  dynamic_reconfigure::Config values;
  request.__toMessage__(values);
  std::string error;
  std::optional<C> next = reconfigured(table, running, values, error);
  if (!next) {
    keepRunningValues(request, std::make_pair(std::cref(table), running));
    monitor.error(what + " refused: " + error);
    log.error(what + " refused, running values kept: " + error);
  }
  return next;
}

/// As above for a stage whose run-time parameters come from two tables (the
/// TSDF's map config and node options): both are checked before either
/// changes, and a refusal writes both tables' running values back.
template <class C1, class C2, class Cfg>
std::optional<std::pair<C1, C2>> checkedReconfigure(Cfg& request, const ParamTable<C1>& table1, const C1& running1,
                                                    const ParamTable<C2>& table2, const C2& running2,
                                                    StageMonitor& monitor, const NodeletLogger& log,
                                                    const std::string& what) {
  dynamic_reconfigure::Config values;
  request.__toMessage__(values);
  std::string error;
  std::optional<C1> next1 = reconfigured(table1, running1, values, error);
  std::optional<C2> next2;
  if (next1) next2 = reconfigured(table2, running2, values, error);
  if (next1 && next2) return std::make_pair(std::move(*next1), std::move(*next2));
  keepRunningValues(request, std::make_pair(std::cref(table1), running1), std::make_pair(std::cref(table2), running2));
  monitor.error(what + " refused: " + error);
  log.error(what + " refused, running values kept: " + error);
  return std::nullopt;
}

template <class F>
bool guarded(StageMonitor& monitor, NodeletLogger& log, const std::string& what, const ros::Time& stamp, F&& f,
             double throttle_s) {
  try {
    f();
    return true;
  } catch (const std::exception& e) {
    noteCallbackError(monitor, log, what, stamp, e.what(), throttle_s);
  } catch (...) {
    noteCallbackError(monitor, log, what, stamp, "unknown exception", throttle_s);
  }
  return false;
}

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_ROS_NODELET_GLUE_H_
