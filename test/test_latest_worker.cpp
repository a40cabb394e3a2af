// LatestWorker: the newest item wins, a waiting item is replaced, stop() ends
// the thread without working on what waits.
#include <future>
#include <vector>

#include <gtest/gtest.h>

#include "fisheye_mapping/core/common/latest_worker.h"

namespace fm = fisheye_mapping;

TEST(LatestWorker, AWaitingItemIsReplacedByTheNewest) {
  std::promise<void> started, release;
  std::shared_future<void> go = release.get_future().share();
  std::mutex m;
  std::vector<int> done;
  std::promise<void> finished;
  {
    fm::LatestWorker<int> worker([&](int& i) {
      if (i == 1) {
        started.set_value();
        go.wait();  // item 1 in work while 2, 3 and 4 arrive
      }
      std::lock_guard<std::mutex> lock(m);
      done.push_back(i);
      if (i == 4) finished.set_value();
    });
    EXPECT_FALSE(worker.offer(1));
    started.get_future().wait();
    EXPECT_FALSE(worker.offer(2));  // the slot was empty: 1 is in work
    EXPECT_TRUE(worker.offer(3));   // replaces 2
    EXPECT_TRUE(worker.offer(4));   // replaces 3
    release.set_value();
    ASSERT_EQ(finished.get_future().wait_for(std::chrono::seconds(10)), std::future_status::ready);
  }
  EXPECT_EQ(done, (std::vector<int>{1, 4}));
}

// A mailbox of two (paced input with two frame sets in flight): two items may
// wait, in order; a third drops the oldest waiting one.
TEST(LatestWorker, AMailboxOfTwoKeepsTwoWaitingItemsInOrder) {
  std::promise<void> started, release;
  std::shared_future<void> go = release.get_future().share();
  std::mutex m;
  std::vector<int> done;
  std::promise<void> finished;
  {
    fm::LatestWorker<int> worker(
        [&](int& i) {
          if (i == 1) {
            started.set_value();
            go.wait();
          }
          std::lock_guard<std::mutex> lock(m);
          done.push_back(i);
          if (i == 4) finished.set_value();
        },
        2);
    EXPECT_FALSE(worker.offer(1));
    started.get_future().wait();
    EXPECT_FALSE(worker.offer(2));
    EXPECT_FALSE(worker.offer(3));  // 2 and 3 wait
    EXPECT_TRUE(worker.offer(4));   // drops 2, the oldest waiting
    release.set_value();
    ASSERT_EQ(finished.get_future().wait_for(std::chrono::seconds(10)), std::future_status::ready);
  }
  EXPECT_EQ(done, (std::vector<int>{1, 3, 4}));
  EXPECT_THROW(fm::LatestWorker<int>([](int&) {}, 0), std::invalid_argument);
}

TEST(LatestWorker, StopDropsTheWaitingItem) {
  std::promise<void> started, release;
  std::shared_future<void> go = release.get_future().share();
  std::vector<int> done;
  fm::LatestWorker<int> worker([&](int& i) {
    if (i == 1) {
      started.set_value();
      go.wait();
    }
    done.push_back(i);
  });
  worker.offer(1);
  started.get_future().wait();
  worker.offer(2);
  std::thread stopper([&] { worker.stop(); });
  std::this_thread::sleep_for(std::chrono::milliseconds(50));  // stop() waits for item 1
  release.set_value();
  stopper.join();
  EXPECT_EQ(done, (std::vector<int>{1}));
  worker.stop();  // idempotent
}
