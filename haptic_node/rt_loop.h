// Fixed-rate loop timing on absolute deadlines (CLOCK_MONOTONIC), with real-time scheduling when allowed.
#pragma once
#include <cstdint>
#include <string>

namespace surgsim {

/// What the process got when asking for real-time behaviour (each item is best effort).
struct RealtimeStatus {
  bool fifo = false;     // SCHED_FIFO granted
  bool locked = false;   // mlockall(MCL_CURRENT | MCL_FUTURE) succeeded
  bool slack = false;    // timer slack set to 1 ns
  std::string note;      // human-readable summary, e.g. "SCHED_FIFO 80, memory locked"
};

/// Asks for SCHED_FIFO at `priority` (0 = don't), locked memory, 1 ns timer slack and, when `cpu` >= 0, pins the
/// calling thread to that CPU. Never fails: what was refused is reported in the note. Call from the thread that will
/// run the loop, during init.
RealtimeStatus enter_realtime(int priority, bool lock_memory, int cpu = -1);

/// Paces a loop at a fixed period on absolute deadlines. Tick k is due at start + k * period. wait() sleeps with
/// clock_nanosleep(TIMER_ABSTIME) until `spin_ns` before the deadline, then spins. A tick that has not finished
/// by the next deadline is a miss; when the loop falls more than `max_behind` periods behind it re-anchors instead
/// of bursting to catch up (the skipped ticks count as misses). Allocates nothing.
class PeriodicTimer {
 public:
  PeriodicTimer(std::int64_t period_ns, std::int64_t spin_ns = 150000, int max_behind = 2);
  void start();                        // first deadline = now + period
  /// Waits for the next deadline; returns how late the wake-up was (ns, >= 0).
  std::int64_t wait();
  std::int64_t period_ns() const { return period_ns_; }
  std::int64_t misses() const { return misses_; }
  std::int64_t next_deadline_ns() const { return next_ns_; }

 private:
  std::int64_t period_ns_;
  std::int64_t spin_ns_;
  int max_behind_;
  std::int64_t next_ns_ = 0;
  std::int64_t misses_ = 0;
};

}  // namespace surgsim
