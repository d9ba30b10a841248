// CPU placement: the haptic node keeps one CPU for its loop and every other thread off it.
#include "os/cpu_affinity.h"

#include <gtest/gtest.h>

#include <atomic>
#include <future>
#include <thread>

using namespace surgsim::os;

namespace surgsim {
namespace {

// A thread that is already running (as a library's pool is) until release() is called; reports its affinity.
class Bystander {
 public:
  Bystander() : thread_([this] {
    while (!stop_.load()) {
      if (ask_.exchange(false)) {
        cpus_ = allowed_cpus();
        answered_.store(true);
      }
      std::this_thread::yield();
    }
  }) {}
  ~Bystander() {
    stop_.store(true);
    thread_.join();
  }
  std::vector<int> cpus() {
    answered_.store(false);
    ask_.store(true);
    while (!answered_.load()) std::this_thread::yield();
    return cpus_;
  }

 private:
  std::atomic<bool> stop_{false}, ask_{false}, answered_{false};
  std::vector<int> cpus_;
  std::thread thread_;
};

// Runs f on a fresh thread (so that the test's own thread can restore every affinity afterwards).
template <class F>
void on_a_thread(F f) {
  std::thread t(f);
  t.join();
}

TEST(CpuAffinity, CpuListWritesRanges) {
  EXPECT_EQ(cpu_list({}), "none");
  EXPECT_EQ(cpu_list({0}), "0");
  EXPECT_EQ(cpu_list({0, 1}), "0-1");
  EXPECT_EQ(cpu_list({0, 1, 2, 5, 7, 8}), "0-2,5,7-8");
}

// keep_off_cpu moves the calling thread, the threads it starts afterwards and the threads already running; only the
// thread then pinned to the CPU may run there.
TEST(CpuAffinity, KeepOffCpuMovesEveryOtherThreadOffIt) {
  const std::vector<int> all = allowed_cpus();
  if (all.size() < 2) GTEST_SKIP() << "needs 2 CPUs, this process may use " << cpu_list(all);
  const int loop_cpu = all.front();
  std::vector<int> rest(all.begin() + 1, all.end());
  {
    Bystander bystander;  // started before keep_off_cpu, like OpenBLAS's pool at load time
    ASSERT_EQ(bystander.cpus(), all);
    on_a_thread([&] {
      const std::string note = keep_off_cpu(loop_cpu);
      EXPECT_EQ(note, "other threads on CPUs " + cpu_list(rest));
      EXPECT_EQ(allowed_cpus(), rest);
      std::vector<int> started;
      on_a_thread([&] { started = allowed_cpus(); });
      EXPECT_EQ(started, rest);               // a thread started afterwards inherits it
      EXPECT_EQ(bystander.cpus(), rest);      // a thread that was already running was moved
      ASSERT_TRUE(set_thread_cpus({loop_cpu}));  // the loop takes its CPU
      EXPECT_EQ(allowed_cpus(), std::vector<int>{loop_cpu});
      EXPECT_EQ(other_threads_allowed_on(loop_cpu), 0);
    });
  }
  ASSERT_TRUE(set_thread_cpus(all));  // this (gtest's) thread was moved too
}

// On a machine (or a cpuset) with one CPU nothing moves: every thread keeps the only CPU it has.
TEST(CpuAffinity, OneCpuLeavesEveryThreadWhereItWas) {
  const std::vector<int> all = allowed_cpus();
  const int only = all.front();
  on_a_thread([&] {
    ASSERT_TRUE(set_thread_cpus({only}));
    const std::string note = keep_off_cpu(only);
    EXPECT_EQ(note, "other threads not moved (CPU " + std::to_string(only) + " is the only one allowed)");
    EXPECT_EQ(allowed_cpus(), std::vector<int>{only});
  });
  EXPECT_EQ(allowed_cpus(), all);
}

TEST(CpuAffinity, SetThreadCpusRefusesAnEmptyOrImpossibleList) {
  const std::vector<int> before = allowed_cpus();
  EXPECT_FALSE(set_thread_cpus({}));
  EXPECT_FALSE(set_thread_cpus({-1}));
  EXPECT_FALSE(set_thread_cpus({CPU_SETSIZE}));
  EXPECT_EQ(allowed_cpus(), before);
}

}  // namespace
}  // namespace surgsim
