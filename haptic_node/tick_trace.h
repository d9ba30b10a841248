// --tick-trace: one row per tick (its deadline, how late the loop woke, its wall and CPU time, the misses so far and
// the contact step's stages), kept in memory during the loop (preallocated, no allocation per tick) and written as
// CSV after it.
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstdio>

#include "contact/contact_types.h"

namespace surgsim {

struct TickTrace {
  std::uint64_t due_ns = 0;   // the tick's deadline from the loop's start
  std::int64_t late_ns = 0;   // wake-up after the deadline (64 bits, signed: a wake-up seconds late is kept whole)
  std::uint32_t wall_ns = 0;  // the tick's wall time (saturates at 4.29 s)
  std::uint32_t cpu_ns = 0;   // the loop thread's CPU time during it (saturates at 4.29 s)
  std::uint32_t misses = 0;   // missed deadlines counted up to this tick's wake-up (a late tick k shows at k + 1)
  std::array<std::uint32_t, contact::kContactStages> stage_ns{};  // the contact step's stages (0: none, intestine)
};

/// The row of one tick from the loop's readings (ns; misses as counted by the timer). No allocation.
TickTrace tick_trace_row(std::uint64_t due_ns, std::int64_t late_ns, std::uint64_t wall_ns, std::uint64_t cpu_ns,
                         std::int64_t misses) noexcept;

/// Writes the header and rows[0 .. count) to `file` as CSV, times in us (tick,due_us,wake_late_us,tick_us,
/// tick_cpu_us,misses, then one <stage>_us column per contact stage).
void write_tick_trace(std::FILE* file, const TickTrace* rows, std::size_t count);

}  // namespace surgsim
