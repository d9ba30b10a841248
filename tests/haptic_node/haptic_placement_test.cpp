// Where the haptic node's threads run and what its loop records about late ticks, on a real paced run of the
// intestine scene (real Fast DDS, no visual node); the liver's contact stages in the tick trace.
#include <gtest/gtest.h>

#include <array>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "haptic_app.h"
#include "os/cpu_affinity.h"
#include "support/test_domain.h"

using namespace surgsim::os;

namespace surgsim {
namespace {

HapticOptions paced_intestine(const std::string& name) {
  setenv("SURGSIM_CONFIG_DIR", SURGSIM_TEST_CONFIG_DIR, 1);
  HapticOptions o;
  o.scene = "intestine";
  o.quiet = true;
  o.cache_dir = SURGSIM_TEST_CACHE_DIR;
  o.domain = test::reserve_test_domain();
  o.rt_priority = 0;  // no SCHED_FIFO needed: placement and the trace do not depend on it
  o.lock_memory = false;
  o.rate_hz = 1000;
  o.duration = 0.05;  // 50 paced ticks
  o.stats = ::testing::TempDir() + "/" + name + "_stats.json";
  o.tick_trace = ::testing::TempDir() + "/" + name + "_ticks.csv";
  std::filesystem::create_directories(o.cache_dir);
  return o;
}

nlohmann::json run(const HapticOptions& o) {
  {
    HapticApp app(o);
    EXPECT_EQ(app.run(), 0);
    app.shutdown();
  }
  std::ifstream in(o.stats);
  return nlohmann::json::parse(in);
}

// --cpu N: the loop runs on N alone; the DDS, publisher and writer threads and the threads that ran before the node
// started (OpenBLAS's pool) are on the other CPUs.
TEST(HapticPlacement, CpuKeepsTheLoopAloneOnItsCpu) {
  const std::vector<int> all = allowed_cpus();
  if (all.size() < 2) GTEST_SKIP() << "needs 2 CPUs, this process may use " << cpu_list(all);
  HapticOptions o = paced_intestine("placement");
  o.cpu = all.back();
  const nlohmann::json j = run(o);
  set_thread_cpus(all);  // the node moved this (its loop) thread
  const auto& p = j.at("cpu_placement");
  EXPECT_EQ(p.at("loop_cpu").get<int>(), o.cpu);
  EXPECT_EQ(p.at("other_threads_on_loop_cpu").get<int>(), 0) << p.dump();
  std::vector<int> rest(all.begin(), all.end() - 1);
  EXPECT_EQ(p.at("others").get<std::string>(), "other threads on CPUs " + cpu_list(rest));
  EXPECT_NE(j.at("realtime").get<std::string>().find("pinned to CPU " + std::to_string(o.cpu)), std::string::npos);
}

TEST(HapticPlacement, ACpuTheProcessMayNotUseIsRefusedWithTheChoices) {
  HapticOptions o = paced_intestine("bad_cpu");
  o.cpu = CPU_SETSIZE - 1;
  try {
    HapticApp app(o);
    FAIL() << "--cpu " << o.cpu << " accepted";
  } catch (const std::exception& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("--cpu " + std::to_string(o.cpu) + ": this process may run on CPUs " +
                        cpu_list(allowed_cpus())), std::string::npos) << what;
  }
}

// --tick-trace: one row per tick with its deadline, wake-up lateness, wall and CPU time; the stats give the CPU time
// beside the wall time and the loop thread's context switches and page faults.
// The contact step's stage columns after the timing columns (contact::ContactStage order).
constexpr int kStageColumns = 5;

// Reads a tick trace; checks a row per tick, times from the loop's start within `run_us`, deadlines rising; returns
// the sum of each contact stage's column over the run (us).
std::array<double, kStageColumns> expect_trace(const std::string& path, int ticks, double run_us) {
  std::array<double, kStageColumns> stage_sum{};
  std::ifstream in(path);
  std::string line;
  EXPECT_TRUE(std::getline(in, line));
  EXPECT_EQ(line,
            "tick,due_us,wake_late_us,tick_us,tick_cpu_us,misses,track_points_us,build_patches_us,"
            "solve_active_set_us,friction_us,distribute_forces_us");
  int rows = 0;
  double last_due = -1;
  while (std::getline(in, line)) {
    std::stringstream s(line);
    std::string f[6 + kStageColumns];
    for (auto& v : f) std::getline(s, v, ',');
    double stages = 0;
    for (int c = 0; c < kStageColumns; ++c) {
      // Written from unsigned counters (never negative): a wrapped one would read as seconds, longer than its tick.
      const double us = std::stod(f[6 + c]);
      EXPECT_LE(us, std::stod(f[3]) + 0.01) << "tick " << rows << " stage " << c;
      stage_sum[static_cast<std::size_t>(c)] += us;
      stages += us;
    }
    // The stages are timed inside the tick: together never longer than it (each column is rounded to 1 ns).
    EXPECT_LE(stages, std::stod(f[3]) + 0.01) << "tick " << rows;
    EXPECT_EQ(std::stoi(f[0]), rows);
    const double due = std::stod(f[1]);
    EXPECT_GT(due, last_due);
    EXPECT_LT(due, run_us) << "tick " << rows;
    last_due = due;
    // The wake-up's lateness is written signed: never negative (the timer spins to the deadline), never as long as the
    // run.
    const double late = std::stod(f[2]);
    EXPECT_GE(late, 0.0) << "tick " << rows;
    EXPECT_LT(late, run_us) << "tick " << rows;
    EXPECT_GT(std::stod(f[3]), 0.0);
    EXPECT_GT(std::stod(f[4]), 0.0);
    ++rows;
  }
  EXPECT_EQ(rows, ticks);
  return stage_sum;
}

TEST(HapticPlacement, TickTraceHasEveryTick) {
  HapticOptions o = paced_intestine("trace");
  const nlohmann::json j = run(o);
  const auto stages = expect_trace(o.tick_trace, 50, 60e6);  // the whole run, start-up included, is far below a minute
  for (const double us : stages) EXPECT_EQ(us, 0.0);         // the intestine has no contact stages
  EXPECT_EQ(j.at("tick_cpu_us").at("count").get<int>(), 50);
  EXPECT_TRUE(j.contains("loop_involuntary_switches"));
  EXPECT_TRUE(j.contains("loop_page_faults"));
  EXPECT_TRUE(j.at("cpu_latency").is_string());
}

// Unpaced (--speed max) a tick has no deadline: the trace gives when the tick started (it wrote 0 minus the loop's
// start, wrapped around to about 1.8e13 us).
TEST(HapticPlacement, TickTraceOfAnUnpacedRunGivesTheTicksStart) {
  HapticOptions o = paced_intestine("trace_unpaced");
  o.speed = 0;
  run(o);
  expect_trace(o.tick_trace, 50, 60e6);
}

// The liver's contact step is timed stage by stage: a poke that presses in spends time tracking points, building
// patches, solving and distributing forces (the friction stage has nothing to do without friction: any time >= 0).
TEST(HapticPlacement, TickTraceTimesTheLiversContactStages) {
  HapticOptions o = paced_intestine("trace_liver");
  o.scene = "liver";
  o.replay = std::string(SURGSIM_TEST_CONFIG_DIR) + "/trajectories/liver_poke.csv";
  o.speed = 0;
  o.duration = 2.5;  // 2500 ticks: the tip enters the organ at about 1.3 s
  run(o);
  const auto stages = expect_trace(o.tick_trace, 2500, 60e6);
  for (const int c : {0, 1, 2, 4}) EXPECT_GT(stages[static_cast<std::size_t>(c)], 0.0) << "stage " << c << " never ran";
}

}  // namespace
}  // namespace surgsim
