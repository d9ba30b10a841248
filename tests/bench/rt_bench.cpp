// rt_bench: the machine's own floor for a 1 kHz loop. Runs the haptic node's PeriodicTimer (SCHED_FIFO, locked
// memory, 1 ns timer slack, sleep then spin, and by default the node's CPU wake-up latency request of 0 us,
// os/cpu_latency.h; --cpu-latency-us -1 measures the machine without it) with a fixed busy "tick" and no DDS, no
// model, nothing else, and counts
// missed deadlines and wake-up lateness exactly as haptic_node does. Run it alone and next to other processes
// (scripts/report.sh runs it alone, then next to a haptic node) to tell the node's misses from the machine's.
//   build/bench/rt_bench [--seconds 20] [--rate 1000] [--work-us 50] [--cpu-latency-us 0] [--label alone] [--out DIR]
// --out DIR appends a row to DIR/rt_floor.csv. A plain program (never a pass/fail test).
#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdio>
#include <string>

#include "core/clock.h"
#include "csv_out.h"
#include "os/cpu_latency.h"
#include "rt_loop.h"
#include "core/stats.h"

using namespace surgsim::core;
using namespace surgsim::os;

int main(int argc, char** argv) {
  double seconds = 20, rate = 1000, work_us = 50;
  int priority = 80, cpu = -1, cpu_latency_us = 0;
  std::string label = "alone", out;
  CLI::App app{"rt_bench: missed deadlines and wake-up lateness of the haptic node's loop timer with a fixed busy tick "
               "and nothing else (the machine's floor), to compare with haptic_node's stats."};
  app.add_option("--seconds", seconds, "Run time")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--rate", rate, "Loop rate, Hz")->capture_default_str()->check(CLI::Range(1.0, 20000.0));
  app.add_option("--work-us", work_us, "Busy time per tick, us (haptic_node's tick p50 is about 20-50 us)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option("--rt-priority", priority, "SCHED_FIFO priority (0 = normal scheduling)")->capture_default_str();
  app.add_option("--cpu", cpu, "Pin the loop to this CPU (default: not pinned)");
  app.add_option("--cpu-latency-us", cpu_latency_us, "CPU wake-up latency request while the loop runs, as haptic_node "
                 "asks by default (0: idle CPUs poll; -1: ask nothing, the machine as it idles)")
      ->capture_default_str();
  app.add_option("--label", label, "Name of the condition (a CSV column), e.g. alone, next-to-haptic-node")
      ->capture_default_str();
  app.add_option("--out", out, "Append a row to DIR/rt_floor.csv (written with a header when new)");
  CLI11_PARSE(app, argc, argv);
  if (work_us * 1e-6 >= 1.0 / rate) {
    std::fprintf(stderr, "rt_bench: --work-us %.0f does not fit in a %.0f us period (lower it)\n", work_us, 1e6 / rate);
    return 2;
  }

  using namespace surgsim;
  const auto ticks = static_cast<std::size_t>(std::llround(seconds * rate));
  SampleRecorder late(ticks + 1), busy(ticks + 1);
  const RealtimeStatus rt = enter_realtime(priority, true, cpu);
  const CpuLatencyRequest latency(cpu_latency_us);
  PeriodicTimer timer(static_cast<std::int64_t>(std::llround(1e9 / rate)));
  const auto work_ns = static_cast<std::uint64_t>(work_us * 1e3);
  timer.start();
  for (std::size_t k = 0; k < ticks; ++k) {
    late.add(static_cast<double>(timer.wait()) * 1e-3);
    const std::uint64_t t0 = monotonic_ns();
    while (monotonic_ns() - t0 < work_ns) {
    }
    busy.add(static_cast<double>(monotonic_ns() - t0) * 1e-3);
  }
  const Percentiles l = late.summary(), b = busy.summary();
  const double missed_pct = 100.0 * static_cast<double>(timer.misses()) / static_cast<double>(ticks);
  std::printf("rt_bench [%s]: %zu ticks at %.0f Hz, %s, %s; %lld missed (%.3f %%); wake-up late p50 %.1f / p99 %.1f / "
              "max %.1f us; busy tick max %.1f us (asked %.0f)\n",
              label.c_str(), ticks, rate, rt.note.c_str(), latency.note().c_str(),
              static_cast<long long>(timer.misses()), missed_pct, l.p50, l.p99, l.max, b.max, work_us);
  try {
    bench::CsvOut csv(out, "rt_floor",
                      "condition,ticks,rate_hz,work_us,realtime,missed,missed_pct,late_us_p50,late_us_p99,late_us_max,"
                      "busy_us_max",
                      true);
    csv.row("%s,%zu,%.0f,%.0f,%s,%lld,%.4f,%.2f,%.2f,%.1f,%.1f", label.c_str(), ticks, rate, work_us,
            rt.fifo ? "SCHED_FIFO" : "normal", static_cast<long long>(timer.misses()), missed_pct, l.p50, l.p99, l.max,
            b.max);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "rt_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
