// fork_child.h: runs a piece of a benchmark in a forked child, so that its peak resident memory (getrusage
// ru_maxrss) and its allocations are its own, and gets a plain result struct back through a pipe.
#pragma once
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <exception>

namespace surgsim::bench {

/// Peak resident memory of this process so far, MiB.
inline double maxrss_mib() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return static_cast<double>(ru.ru_maxrss) / 1024.0;
}

/// Calls work(result) in a child process and returns the child's result. Result: trivially copyable, with
/// `int ok` (set to 1 when work returns) and `char error[N]` (the exception's message, or why the child failed).
template <typename Result, typename F>
Result in_child(F&& work) {
  int fd[2];
  Result r{};
  if (pipe(fd) != 0) {
    std::snprintf(r.error, sizeof r.error, "pipe failed");
    return r;
  }
  std::fflush(nullptr);
  const pid_t pid = fork();
  if (pid == 0) {
    close(fd[0]);
    try {
      work(r);
      r.ok = 1;
    } catch (const std::exception& e) {
      std::snprintf(r.error, sizeof r.error, "%s", e.what());
    }
    std::fflush(nullptr);
    const ssize_t w = write(fd[1], &r, sizeof r);
    _exit(w == static_cast<ssize_t>(sizeof r) ? 0 : 1);
  }
  close(fd[1]);
  const ssize_t got = read(fd[0], &r, sizeof r);
  close(fd[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  if (got != static_cast<ssize_t>(sizeof r)) {
    r = Result{};
    std::snprintf(r.error, sizeof r.error, "child failed (status %d)", status);
  }
  return r;
}

}  // namespace surgsim::bench
