#include "os/cpu_affinity.h"

#include <dirent.h>
#include <sched.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>

namespace surgsim::os {
namespace {

std::vector<int> cpus_of(const cpu_set_t& set) {
  std::vector<int> cpus;
  for (int c = 0; c < CPU_SETSIZE; ++c) {
    if (CPU_ISSET(c, &set)) cpus.push_back(c);
  }
  return cpus;
}

}  // namespace

std::vector<int> allowed_cpus() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) != 0) return {};
  return cpus_of(set);
}

std::string cpu_list(const std::vector<int>& cpus) {
  if (cpus.empty()) return "none";
  std::string s;
  for (std::size_t i = 0; i < cpus.size();) {
    std::size_t j = i;
    while (j + 1 < cpus.size() && cpus[j + 1] == cpus[j] + 1) ++j;
    if (!s.empty()) s += ",";
    s += std::to_string(cpus[i]);
    if (j > i) s += "-" + std::to_string(cpus[j]);
    i = j + 1;
  }
  return s;
}

bool set_thread_cpus(const std::vector<int>& cpus) {
  if (cpus.empty()) return false;
  cpu_set_t set;
  CPU_ZERO(&set);
  for (int c : cpus) {
    if (c < 0 || c >= CPU_SETSIZE) return false;
    CPU_SET(c, &set);
  }
  return sched_setaffinity(0, sizeof set, &set) == 0;
}

namespace {

/// Calls f(tid) for every thread of this process but the calling one; false when /proc cannot be read.
template <class F>
bool for_other_threads(F&& f) {
  DIR* dir = opendir("/proc/self/task");
  if (dir == nullptr) return false;
  const auto self = static_cast<pid_t>(syscall(SYS_gettid));
  while (dirent* e = readdir(dir)) {
    const auto tid = static_cast<pid_t>(std::atoi(e->d_name));
    if (tid > 0 && tid != self) f(tid);
  }
  closedir(dir);
  return true;
}

}  // namespace

std::string keep_off_cpu(int cpu) {
  std::vector<int> others = allowed_cpus();
  others.erase(std::remove(others.begin(), others.end(), cpu), others.end());
  if (others.empty()) {
    return "other threads not moved (CPU " + std::to_string(cpu) + " is the only one allowed)";
  }
  if (!set_thread_cpus(others)) return "other threads not moved (CPUs " + cpu_list(others) + " refused)";
  cpu_set_t set;
  CPU_ZERO(&set);
  for (int c : others) CPU_SET(c, &set);
  int refused = 0;
  for_other_threads([&](pid_t tid) { refused += sched_setaffinity(tid, sizeof set, &set) != 0; });
  return "other threads on CPUs " + cpu_list(others) +
         (refused > 0 ? " (" + std::to_string(refused) + " running threads refused to move)" : "");
}

int other_threads_allowed_on(int cpu) {
  int count = 0;
  const bool read = for_other_threads([&](pid_t tid) {
    cpu_set_t set;
    CPU_ZERO(&set);
    if (sched_getaffinity(tid, sizeof set, &set) == 0 && CPU_ISSET(cpu, &set)) ++count;
  });
  return read ? count : -1;
}

}  // namespace surgsim::os
