#include "os/thread_priority.h"

#include <gtest/gtest.h>
#include <pthread.h>

#include <thread>

using namespace surgsim::os;

namespace surgsim {
namespace {

struct Sched {
  int policy = -1;
  int priority = -1;
};

// Asks the kernel (not glibc's per-thread cache) how the calling thread is scheduled.
Sched of_this_thread() {
  Sched s;
  s.policy = sched_getscheduler(0);
  sched_param p{};
  sched_getparam(0, &p);
  s.priority = p.sched_priority;
  return s;
}

Sched of_a_new_thread() {
  Sched s;
  std::thread t([&] { s = of_this_thread(); });
  t.join();
  return s;
}

TEST(ScopedFifo, ZeroLeavesTheThreadAlone) {
  const Sched before = of_this_thread();
  {
    ScopedFifo scope(0);
    EXPECT_FALSE(scope.raised());
    EXPECT_NE(scope.note().find("priority 0"), std::string::npos) << scope.note();
    EXPECT_EQ(of_a_new_thread().policy, before.policy);
  }
  EXPECT_EQ(of_this_thread().policy, before.policy);
}

// What the nodes rely on: threads started inside the scope (Fast DDS's) run at SCHED_FIFO, the creating thread goes
// back to its own scheduling afterwards, and threads it starts later (llvmpipe's, writers') are normal again.
TEST(ScopedFifo, ThreadsStartedInsideInheritFifoAndTheCreatorReturns) {
  const Sched before = of_this_thread();
  ASSERT_EQ(before.policy, SCHED_OTHER);
  Sched inside;
  {
    ScopedFifo scope(20);
    if (!scope.raised()) {
      EXPECT_NE(scope.note().find("refused"), std::string::npos) << scope.note();
      GTEST_SKIP() << "SCHED_FIFO not permitted here: " << scope.note();
    }
    EXPECT_EQ(scope.note(), "SCHED_FIFO 20");
    inside = of_a_new_thread();
  }
  EXPECT_EQ(inside.policy, SCHED_FIFO);
  EXPECT_EQ(inside.priority, 20);
  const Sched after = of_this_thread();
  EXPECT_EQ(after.policy, before.policy);
  EXPECT_EQ(after.priority, before.priority);
  EXPECT_EQ(of_a_new_thread().policy, SCHED_OTHER);
}

}  // namespace
}  // namespace surgsim
