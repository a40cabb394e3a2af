// A worker thread fed through a mailbox of `capacity` items (default 1): the
// newest items win. For a stage slower than its input (the depth stage's
// sweep): an item that arrives while the mailbox is full replaces the oldest
// waiting one, and the caller counts the one dropped. A capacity above 1 is
// for input that is itself paced (a paced player with several frame sets in
// flight), where nothing should be dropped. Header-only, no ROS.
#ifndef FISHEYE_MAPPING_CORE_COMMON_LATEST_WORKER_H_
#define FISHEYE_MAPPING_CORE_COMMON_LATEST_WORKER_H_

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>
#include <utility>

namespace fisheye_mapping {

template <class T>
class LatestWorker {
 public:
  /// Starts the thread; `work` runs on it, one item at a time, in the order
  /// they came. Throws std::invalid_argument for a capacity below 1.
  explicit LatestWorker(std::function<void(T&)> work, int capacity = 1)
      : work_(std::move(work)), capacity_(checked(capacity)), thread_([this] { run(); }) {}
  ~LatestWorker() { stop(); }
  LatestWorker(const LatestWorker&) = delete;
  LatestWorker& operator=(const LatestWorker&) = delete;

  /// Hands `item` to the worker. True when the mailbox was full and the
  /// oldest waiting item was dropped (never worked on). Thread-safe.
  bool offer(T item) {
    bool replaced;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      replaced = static_cast<int>(waiting_.size()) >= capacity_;
      if (replaced) waiting_.pop_front();
      waiting_.push_back(std::move(item));
    }
    cv_.notify_one();
    return replaced;
  }

  /// Stops the thread: the item in work finishes, waiting ones are dropped.
  /// Idempotent; not from inside `work`.
  void stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }

 private:
  void run() {
    for (;;) {
      std::optional<T> item;
      {
        std::unique_lock<std::mutex> lock(mutex_);
        cv_.wait(lock, [this] { return stopping_ || !waiting_.empty(); });
        if (stopping_) return;
        item.emplace(std::move(waiting_.front()));
        waiting_.pop_front();
      }
      work_(*item);
    }
  }

  static int checked(int capacity) {
    if (capacity < 1) throw std::invalid_argument("a worker's mailbox holds at least 1 item");
    return capacity;
  }

  std::function<void(T&)> work_;
  int capacity_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<T> waiting_;
  bool stopping_ = false;
  std::thread thread_;  // last: started once the rest exists
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_LATEST_WORKER_H_
