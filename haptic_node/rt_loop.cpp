#include "rt_loop.h"

#include <sched.h>
#include <sys/mman.h>
#include <sys/prctl.h>

#include <cerrno>
#include <cstring>
#include <ctime>

#include "core/clock.h"
#include "os/cpu_affinity.h"

using namespace surgsim::core;
using namespace surgsim::os;

namespace surgsim {

RealtimeStatus enter_realtime(int priority, bool lock_memory, int cpu) {
  RealtimeStatus s;
  std::string note;
  if (cpu >= 0) {
    note += set_thread_cpus({cpu}) ? "pinned to CPU " + std::to_string(cpu) + ", "
                                   : "CPU " + std::to_string(cpu) + " refused, ";
  }
  if (priority > 0) {
    sched_param sp{};
    sp.sched_priority = priority;
    if (sched_setscheduler(0, SCHED_FIFO, &sp) == 0) {
      s.fifo = true;
      note += "SCHED_FIFO " + std::to_string(priority);
    } else {
      note += std::string("SCHED_FIFO refused (") + std::strerror(errno) + "; run as root or grant CAP_SYS_NICE)";
    }
  } else {
    note += "normal scheduling (--rt-priority 0)";
  }
  if (lock_memory) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
    // A sanitizer reserves terabytes of shadow memory: locking every mapping would try to fault all of it in.
    note += ", mlockall skipped (sanitizer build)";
#else
    if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
      s.locked = true;
      note += ", memory locked";
    } else {
      note += std::string(", mlockall refused (") + std::strerror(errno) + ")";
    }
#endif
  }
  if (prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0) == 0) s.slack = true;
  s.note = note;
  return s;
}

PeriodicTimer::PeriodicTimer(std::int64_t period_ns, std::int64_t spin_ns, int max_behind)
    : period_ns_(period_ns), spin_ns_(spin_ns < period_ns ? spin_ns : period_ns / 2), max_behind_(max_behind) {}

void PeriodicTimer::start() {
  next_ns_ = static_cast<std::int64_t>(monotonic_ns()) + period_ns_;
  misses_ = 0;
}

std::int64_t PeriodicTimer::wait() {
  std::int64_t now = static_cast<std::int64_t>(monotonic_ns());
  // The previous tick overran the deadline it had to meet.
  if (now > next_ns_) {
    ++misses_;
    const std::int64_t behind = (now - next_ns_) / period_ns_;
    if (behind >= max_behind_) {
      misses_ += behind;
      next_ns_ = now + period_ns_;  // re-anchor rather than burst
    }
  }
  // Sleep to shortly before the deadline, then spin for precision.
  const std::int64_t wake = next_ns_ - spin_ns_;
  if (now < wake) {
    timespec ts{static_cast<time_t>(wake / 1000000000), static_cast<long>(wake % 1000000000)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
  }
  while ((now = static_cast<std::int64_t>(monotonic_ns())) < next_ns_) {
  }
  const std::int64_t late = now - next_ns_;
  next_ns_ += period_ns_;
  return late;
}

}  // namespace surgsim
