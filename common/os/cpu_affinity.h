// CPU placement of threads. On a PREEMPT_NONE kernel (Debian's cloud kernels, this CI machine's) a
// SCHED_FIFO thread that wakes on a CPU where another process is inside a system call, a page fault or a TLB
// shootdown waits until that kernel path ends; the renderer's kernel time then shows up as the haptic loop's
// lateness. So the haptic node can keep one CPU for its loop thread and put every other thread it starts (DDS,
// publisher, log writers) on the remaining CPUs; scripts/run_local.sh puts the visual node there too.
#pragma once
#include <string>
#include <vector>

namespace surgsim::os {

/// The CPUs the calling thread may run on (sched_getaffinity), ascending.
std::vector<int> allowed_cpus();

/// "0-1,3" for {0, 1, 3}; "none" for an empty list.
std::string cpu_list(const std::vector<int>& cpus);

/// Restricts the calling thread to `cpus` (threads it starts from now on inherit it). False, the affinity unchanged,
/// when the list is empty or the kernel refuses it (a CPU not online or not in the process's cpuset).
bool set_thread_cpus(const std::vector<int>& cpus);

/// Keeps this process's threads off `cpu`: the calling thread, the threads it starts from now on (they inherit its
/// affinity) and the threads that already run (e.g. a BLAS library's pool, started when it was loaded) may run on
/// the calling thread's allowed CPUs except `cpu`. Leaves every affinity alone when that would leave no CPU (a 1-core
/// machine). Returns what it did, e.g. "other threads on CPUs 1" or "other threads not moved (CPU 0 is the only one
/// allowed)". The caller then pins the one thread that is to have `cpu` (set_thread_cpus({cpu})).
std::string keep_off_cpu(int cpu);

/// How many threads of this process other than the calling one may run on `cpu` (reads /proc/self/task; allocates:
/// not for real-time code). -1 when /proc cannot be read.
int other_threads_allowed_on(int cpu);

}  // namespace surgsim::os
