// Monotonic time in nanoseconds (the stamp clock of every DDS message).
#pragma once
#include <cstdint>
#include <ctime>

namespace surgsim::core {

inline std::uint64_t monotonic_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::uint64_t>(ts.tv_sec) * 1000000000ull + static_cast<std::uint64_t>(ts.tv_nsec);
}

}  // namespace surgsim::core
