// bench_util.h: small helpers shared by the bench programs (plain programs printing tables, run by hand): the
// calling thread's CPU time, percentiles of a sample vector and an output folder for the CSV files of --out
// (csv_out.h writes them).
#pragma once
#include <time.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <string>
#include <sys/stat.h>
#include <vector>

namespace surgsim::bench {

using WallClock = std::chrono::steady_clock;

/// Wall-clock microseconds since t0.
inline double us_since(WallClock::time_point t0) {
  return std::chrono::duration<double, std::micro>(WallClock::now() - t0).count();
}

/// CPU time of this thread (us): unlike the wall clock it does not count the time the scheduler gave to other
/// processes (the build machine is shared), so its percentiles show the measured code's own cost.
inline double thread_cpu_us() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e6 * static_cast<double>(ts.tv_sec) + 1e-3 * static_cast<double>(ts.tv_nsec);
}

/// The q-quantile (0..1, nearest rank below) of `v`; 0 for an empty vector.
inline double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

/// Makes `dir` (and its parents) if missing; throws std::runtime_error when it cannot.
inline void make_dirs(const std::string& dir) {
  if (dir.empty()) return;
  for (std::size_t pos = 1; pos <= dir.size(); ++pos) {
    if (pos != dir.size() && dir[pos] != '/') continue;
    const std::string part = dir.substr(0, pos);
    if (::mkdir(part.c_str(), 0755) != 0 && errno != EEXIST)
      throw std::runtime_error(part + ": cannot create: " + std::strerror(errno));
  }
}

}  // namespace surgsim::bench
