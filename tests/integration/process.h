// Launching real node processes from tests: spawn with arguments and extra environment, wait with a timeout.
#pragma once
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace surgsim::testing {

/// A child process; killed (SIGKILL) on destruction if still running.
class Process {
 public:
  Process(const std::string& program, const std::vector<std::string>& args, const std::vector<std::string>& env_extra,
          const std::string& output_file) {
    std::vector<std::string> argv_s{program};
    argv_s.insert(argv_s.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : argv_s) argv.push_back(a.data());
    argv.push_back(nullptr);
    std::vector<std::string> env_s;
    for (char** e = environ; *e != nullptr; ++e) env_s.emplace_back(*e);
    env_s.insert(env_s.end(), env_extra.begin(), env_extra.end());
    std::vector<char*> envp;
    for (auto& e : env_s) envp.push_back(e.data());
    envp.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, output_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    const int rc = posix_spawn(&pid_, program.c_str(), &fa, nullptr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) throw std::runtime_error("cannot start " + program);
  }
  ~Process() {
    if (pid_ > 0 && !done_) {
      ::kill(pid_, SIGKILL);
      int st;
      waitpid(pid_, &st, 0);
    }
  }
  void signal(int sig) { ::kill(pid_, sig); }
  /// Exit code, or -1 on timeout (process then killed), or 128+signal.
  int wait(double timeout_s) {
    const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (std::chrono::steady_clock::now() < until) {
      int st = 0;
      const pid_t r = waitpid(pid_, &st, WNOHANG);
      if (r == pid_) {
        done_ = true;
        if (WIFEXITED(st)) return WEXITSTATUS(st);
        if (WIFSIGNALED(st)) return 128 + WTERMSIG(st);
        return -2;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    ::kill(pid_, SIGKILL);
    int st;
    waitpid(pid_, &st, 0);
    done_ = true;
    return -1;
  }

 private:
  pid_t pid_ = -1;
  bool done_ = false;
};

inline std::string read_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// CLOCK_MONOTONIC in ns: the clock the nodes stamp with (their stats' loop_start_ns), to place events seen from
/// outside on a node's timeline.
inline std::uint64_t now_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::uint64_t>(ts.tv_sec) * 1000000000ull + static_cast<std::uint64_t>(ts.tv_nsec);
}

/// Polls `done` every 10 ms until it holds (true) or `timeout_s` passes (false).
inline bool wait_until(const std::function<bool()>& done, double timeout_s) {
  const std::uint64_t until = now_ns() + static_cast<std::uint64_t>(timeout_s * 1e9);
  while (now_ns() < until) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return done();
}

/// Waits until `file` contains `text` (true) or `timeout_s` passes (false), polling every 10 ms.
inline bool wait_for_text(const std::string& file, const std::string& text, double timeout_s) {
  return wait_until([&] { return read_file(file).find(text) != std::string::npos; }, timeout_s);
}

}  // namespace surgsim::testing
