// Items that wait, in the order they came, for something named by a key (the
// TSDF stage's depth frames for their camera's first CameraInfo, which the
// stage before publishes too and which may come after them). Header-only,
// no ROS; not thread-safe (the caller locks).
//
//   - An item whose key is known and behind which nothing waits goes on at
//     once; otherwise it waits, and items behind a waiting one wait with it
//     (so items go on in the order they came).
//   - At most max_waiting wait: the oldest beyond goes on (the caller then
//     processes it without its key: dropped, saying why).
//   - An item waits at most max_wait_s (expire()).
#ifndef FISHEYE_MAPPING_CORE_COMMON_ORDERED_WAIT_H_
#define FISHEYE_MAPPING_CORE_COMMON_ORDERED_WAIT_H_

#include <cstddef>
#include <deque>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace fisheye_mapping {

template <class T>
class OrderedWait {
 public:
  using Known = std::function<bool(const std::string& key)>;

  OrderedWait(size_t max_waiting, double max_wait_s) : max_waiting_(max_waiting), max_wait_s_(max_wait_s) {}

  // `item` with `key` came at `now` (s, any monotonic clock): the items to go
  // on now, in order.
  std::vector<T> arrive(T item, const std::string& key, double now, const Known& known) {
    std::vector<T> out;
    if (waiting_.empty() && known(key)) {
      out.push_back(std::move(item));
      return out;
    }
    waiting_.push_back({std::move(item), key, now});
    while (waiting_.size() > max_waiting_) pop(&out);
    release(known, &out);
    return out;
  }

  // After a key became known: the waiting items at the front whose key is known.
  std::vector<T> release(const Known& known) {
    std::vector<T> out;
    release(known, &out);
    return out;
  }

  // At `now`: the items that waited longer than max_wait_s (their key still
  // unknown, or they would have gone), then those behind them that can go.
  std::vector<T> expire(double now, const Known& known) {
    std::vector<T> out;
    while (!waiting_.empty() && now - waiting_.front().since > max_wait_s_) pop(&out);
    release(known, &out);
    return out;
  }

  size_t size() const { return waiting_.size(); }

 private:
  struct Waiting {
    T item;
    std::string key;
    double since;
  };
  void pop(std::vector<T>* out) {
    out->push_back(std::move(waiting_.front().item));
    waiting_.pop_front();
  }
  void release(const Known& known, std::vector<T>* out) {
    while (!waiting_.empty() && known(waiting_.front().key)) pop(out);
  }

  size_t max_waiting_;
  double max_wait_s_;
  std::deque<Waiting> waiting_;
};

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_ORDERED_WAIT_H_
