// The one-object hand-off (a new liver instance to the loop, the replaced one back): ownership moves with the
// pointer, a full slot refuses a second object and leaves it with the sender, the slot frees what is left in it.
#include "concurrency/hand_off.h"

#include <gtest/gtest.h>

#include <atomic>
#include <memory>
#include <thread>

namespace surgsim::concurrency {
namespace {

struct Counted {
  explicit Counted(int v, int* alive) : value(v), alive(alive) { ++*alive; }
  ~Counted() { --*alive; }
  int value;
  int* alive;
};

TEST(HandOff, OwnershipMovesWithThePointerAndAFullSlotRefuses) {
  int alive = 0;
  {
    HandOff<Counted> slot;
    EXPECT_FALSE(slot.full());
    EXPECT_EQ(slot.take(), nullptr);
    auto a = std::make_unique<Counted>(1, &alive);
    auto b = std::make_unique<Counted>(2, &alive);
    EXPECT_TRUE(slot.post(a));
    EXPECT_EQ(a, nullptr);
    EXPECT_TRUE(slot.full());
    EXPECT_FALSE(slot.post(b));  // full: b stays with the sender
    ASSERT_NE(b, nullptr);
    std::unique_ptr<Counted> got = slot.take();
    ASSERT_NE(got, nullptr);
    EXPECT_EQ(got->value, 1);
    EXPECT_FALSE(slot.full());
    EXPECT_TRUE(slot.post(b));
    EXPECT_EQ(alive, 2);
  }  // the slot frees b; got frees a
  EXPECT_EQ(alive, 0);
}

// Two threads passing objects back and forth: each arrives once, none is lost or freed twice.
TEST(HandOff, ObjectsGoAndComeBackBetweenTwoThreads) {
  int alive = 0;
  HandOff<Counted> to_loop, back;
  constexpr int kObjects = 20000;
  std::atomic<int> received{0};
  std::atomic<bool> loop_done{false};
  std::thread loop([&] {
    int expect = 0;
    while (expect < kObjects) {
      std::unique_ptr<Counted> p = to_loop.take();
      if (p == nullptr) continue;
      if (p->value == expect) received.fetch_add(1);
      ++expect;
      while (!back.post(p)) std::this_thread::yield();
    }
    loop_done.store(true);
  });
  for (int i = 0; i < kObjects; ++i) {
    auto p = std::make_unique<Counted>(i, &alive);
    while (!to_loop.post(p)) {
      back.take();  // frees the returned one on this thread
      std::this_thread::yield();
    }
  }
  while (!loop_done.load()) {  // the loop's last returns
    back.take();
    std::this_thread::yield();
  }
  loop.join();
  back.take();
  EXPECT_EQ(received.load(), kObjects);
  EXPECT_EQ(alive, 0);
}

}  // namespace
}  // namespace surgsim::concurrency
