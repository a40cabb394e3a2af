// A worker thread fed through a one-item mailbox: the newest item wins. For a
// stage slower than its input (the depth stage's sweep): an item that arrives
// while another still waits replaces it, and the caller counts the one
// dropped. Header-only, no ROS.
#ifndef FISHEYE_MAPPING_CORE_COMMON_LATEST_WORKER_H_
#define FISHEYE_MAPPING_CORE_COMMON_LATEST_WORKER_H_

#include <condition_variable>
#include <functional>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>

namespace fisheye_mapping {

template <class T>
class LatestWorker {
 public:
  /// Starts the thread; `work` runs on it, one item at a time.
  explicit LatestWorker(std::function<void(T&)> work) : work_(std::move(work)), thread_([this] { run(); }) {}
  ~LatestWorker() { stop(); }
  LatestWorker(const LatestWorker&) = delete;
  LatestWorker& operator=(const LatestWorker&) = delete;

  /// Hands `item` to the worker. True when it replaced an item that was still
  /// waiting (that one is dropped, never worked on). Thread-safe.
  bool offer(T item) {
    bool replaced;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      replaced = slot_.has_value();
      slot_ = std::move(item);
    }
    cv_.notify_one();
    return replaced;
  }

  /// Stops the thread: the item in work finishes, a waiting one is dropped.
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
        cv_.wait(lock, [this] { return stopping_ || slot_.has_value(); });
        if (stopping_) return;
        item.swap(slot_);
      }
      work_(*item);
    }
  }

  std::function<void(T&)> work_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::optional<T> slot_;
  bool stopping_ = false;
  std::thread thread_;  // last: started once the rest exists
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_LATEST_WORKER_H_
