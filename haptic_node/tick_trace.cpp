#include "tick_trace.h"

#include <algorithm>
#include <limits>

namespace surgsim {

namespace {
// A duration in ns as 32 bits, held at the largest value (4.29 s) rather than wrapped.
std::uint32_t saturate_u32(std::uint64_t ns) {
  return static_cast<std::uint32_t>(std::min<std::uint64_t>(ns, std::numeric_limits<std::uint32_t>::max()));
}
}  // namespace

TickTrace tick_trace_row(std::uint64_t due_ns, std::int64_t late_ns, std::uint64_t wall_ns, std::uint64_t cpu_ns,
                         std::int64_t misses) noexcept {
  TickTrace r;
  r.due_ns = due_ns;
  r.late_ns = late_ns;
  r.wall_ns = saturate_u32(wall_ns);
  r.cpu_ns = saturate_u32(cpu_ns);
  r.misses = static_cast<std::uint32_t>(misses);
  return r;
}

void write_tick_trace(std::FILE* file, const TickTrace* rows, std::size_t count) {
  std::fprintf(file, "tick,due_us,wake_late_us,tick_us,tick_cpu_us,misses");
  for (const char* stage : contact::kContactStageNames) std::fprintf(file, ",%s_us", stage);
  std::fputc('\n', file);
  for (std::size_t k = 0; k < count; ++k) {
    const TickTrace& r = rows[k];
    std::fprintf(file, "%llu,%.3f,%.3f,%.3f,%.3f,%u", static_cast<unsigned long long>(k),
                 static_cast<double>(r.due_ns) * 1e-3, static_cast<double>(r.late_ns) * 1e-3, r.wall_ns * 1e-3,
                 r.cpu_ns * 1e-3, r.misses);
    for (const std::uint32_t ns : r.stage_ns) std::fprintf(file, ",%.3f", ns * 1e-3);
    std::fputc('\n', file);
  }
}

}  // namespace surgsim
