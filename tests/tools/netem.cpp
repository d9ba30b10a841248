// surgsim-netem: a user-space "wire" with netem-like impairments, for kernels without the netem qdisc.
// It opens one TAP device in each of two network namespaces and forwards every Ethernet frame from one to the other
// after a delay, with jitter, reordering and loss drawn from a seeded generator (the same seed and traffic give the
// same decisions). scripts/run_two_hosts.sh --impair starts it and puts the hosts' addresses on the two TAPs.
//
//   surgsim-netem --a /run/netns/H:surg0 --b /run/netns/V:surg0 --impair "delay=5ms,jitter=2ms,loss=5%" --seed 1
//
// Semantics follow netem's: delay + a uniform jitter in [-jitter, +jitter] (never below zero), so jitter larger than
// the packet spacing reorders; reorder=P% sends that share of frames at once (ahead of the delayed ones); loss=P%
// drops frames (ARP and discovery too, as a real lossy link would). Each direction has its own generator.
// Not real-time code: one thread, ppoll on both TAPs with a timeout to the next due frame.
#include <fcntl.h>
#include <linux/if.h>
#include <linux/if_tun.h>
#include <poll.h>
#include <sched.h>
#include <sys/ioctl.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <queue>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "core/clock.h"

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }

struct Impairment {
  double delay_s = 0;
  double jitter_s = 0;
  double loss = 0;     // probability
  double reorder = 0;  // probability
};

// "5ms" / "250us" / "0.005s" / "5" (ms) -> seconds.
double parse_time(const std::string& v, const std::string& key) {
  std::size_t used = 0;
  double x = 0;
  try {
    x = std::stod(v, &used);
  } catch (const std::exception&) {
    throw std::runtime_error("--impair: " + key + "='" + v + "' is not a time (e.g. 5ms)");
  }
  const std::string unit = v.substr(used);
  double scale = 1e-3;
  if (unit == "s") scale = 1;
  else if (unit == "ms" || unit.empty()) scale = 1e-3;
  else if (unit == "us") scale = 1e-6;
  else throw std::runtime_error("--impair: " + key + "='" + v + "': unit must be s, ms or us");
  if (!(x >= 0) || x * scale > 10) throw std::runtime_error("--impair: " + key + "='" + v + "' is out of [0, 10 s]");
  return x * scale;
}

// "5%" / "0.05" -> probability.
double parse_ratio(const std::string& v, const std::string& key) {
  std::size_t used = 0;
  double x = 0;
  try {
    x = std::stod(v, &used);
  } catch (const std::exception&) {
    throw std::runtime_error("--impair: " + key + "='" + v + "' is not a ratio (e.g. 5%)");
  }
  if (v.substr(used) == "%") x /= 100;
  else if (used != v.size()) throw std::runtime_error("--impair: " + key + "='" + v + "' is not a ratio (e.g. 5%)");
  if (!(x >= 0 && x <= 1)) throw std::runtime_error("--impair: " + key + "='" + v + "' is out of [0, 100%]");
  return x;
}

Impairment parse_impairment(const std::string& spec, std::uint64_t& seed) {
  Impairment im;
  std::stringstream ss(spec);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item.empty()) continue;
    const auto eq = item.find('=');
    if (eq == std::string::npos) throw std::runtime_error("--impair: '" + item + "' is not KEY=VALUE");
    const std::string k = item.substr(0, eq), v = item.substr(eq + 1);
    if (k == "delay") im.delay_s = parse_time(v, k);
    else if (k == "jitter") im.jitter_s = parse_time(v, k);
    else if (k == "loss") im.loss = parse_ratio(v, k);
    else if (k == "reorder") im.reorder = parse_ratio(v, k);
    else if (k == "seed") seed = std::stoull(v);
    else throw std::runtime_error("--impair: unknown key '" + k + "' (delay, jitter, loss, reorder, seed)");
  }
  return im;
}

// Opens (creates) TAP `name` inside the network namespace at `ns_path`, then returns to this thread's namespace.
int open_tap_in(const std::string& ns_path, const std::string& name) {
  const int self = ::open("/proc/self/ns/net", O_RDONLY | O_CLOEXEC);
  const int target = ::open(ns_path.c_str(), O_RDONLY | O_CLOEXEC);
  if (self < 0 || target < 0) throw std::runtime_error(ns_path + ": cannot open the network namespace (" + std::strerror(errno) + ")");
  if (::setns(target, CLONE_NEWNET) != 0) {
    throw std::runtime_error(ns_path + ": setns refused (" + std::string(std::strerror(errno)) + "; needs CAP_SYS_ADMIN)");
  }
  const int fd = ::open("/dev/net/tun", O_RDWR | O_NONBLOCK | O_CLOEXEC);
  std::string error;
  if (fd < 0) {
    error = std::string("/dev/net/tun: ") + std::strerror(errno);
  } else {
    ifreq ifr{};
    ifr.ifr_flags = IFF_TAP | IFF_NO_PI;
    std::strncpy(ifr.ifr_name, name.c_str(), IFNAMSIZ - 1);
    if (::ioctl(fd, TUNSETIFF, &ifr) != 0) error = "TUNSETIFF " + name + ": " + std::strerror(errno);
  }
  ::setns(self, CLONE_NEWNET);
  ::close(self);
  ::close(target);
  if (!error.empty()) {
    if (fd >= 0) ::close(fd);
    throw std::runtime_error(ns_path + ": cannot create TAP device (" + error + ")");
  }
  return fd;
}

struct Frame {
  std::uint64_t due_ns;
  std::uint64_t seq;
  std::vector<unsigned char> data;
  bool operator>(const Frame& o) const { return due_ns != o.due_ns ? due_ns > o.due_ns : seq > o.seq; }
};

// One direction of the wire: frames read from `in`, written to `out` when due.
struct Direction {
  std::string name;
  int in = -1, out = -1;
  Impairment im;
  std::mt19937_64 rng;
  std::priority_queue<Frame, std::vector<Frame>, std::greater<Frame>> queue;
  std::uint64_t next_seq = 0, last_sent_seq = 0;
  bool sent_any = false;
  std::uint64_t received = 0, dropped = 0, delivered = 0, reordered = 0, write_errors = 0;
  double delay_sum_s = 0, delay_max_s = 0;

  void read_all(std::vector<unsigned char>& buf) {
    for (;;) {
      const ssize_t n = ::read(in, buf.data(), buf.size());
      if (n <= 0) return;  // EAGAIN: drained
      ++received;
      std::uniform_real_distribution<double> u01(0.0, 1.0);
      // Draw every number for every frame, so one frame's fate does not shift the next frame's draws.
      const double r_loss = u01(rng), r_reorder = u01(rng), r_jitter = u01(rng);
      if (r_loss < im.loss) {
        ++dropped;
        continue;
      }
      double delay = im.delay_s + (2 * r_jitter - 1) * im.jitter_s;
      if (r_reorder < im.reorder) delay = 0;
      delay = std::max(0.0, delay);
      delay_sum_s += delay;
      delay_max_s = std::max(delay_max_s, delay);
      queue.push(Frame{surgsim::core::monotonic_ns() + static_cast<std::uint64_t>(delay * 1e9), next_seq++,
                       std::vector<unsigned char>(buf.begin(), buf.begin() + n)});
    }
  }
  void send_due(std::uint64_t now) {
    while (!queue.empty() && queue.top().due_ns <= now) {
      const Frame& f = queue.top();
      if (::write(out, f.data.data(), f.data.size()) < 0) ++write_errors;
      else ++delivered;
      if (sent_any && f.seq < last_sent_seq) ++reordered;
      last_sent_seq = std::max(last_sent_seq, f.seq);
      sent_any = true;
      queue.pop();
    }
  }
  nlohmann::json stats() const {
    return {{"received", received},     {"dropped", dropped},
            {"delivered", delivered},   {"reordered", reordered},
            {"write_errors", write_errors}, {"in_flight_at_exit", queue.size()},
            {"delay_mean_ms", received > dropped ? delay_sum_s * 1e3 / static_cast<double>(received - dropped) : 0.0},
            {"delay_max_ms", delay_max_s * 1e3}};
  }
};

std::pair<std::string, std::string> split_end(const std::string& s, const char* opt) {
  const auto colon = s.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == s.size()) {
    throw std::runtime_error(std::string(opt) + " '" + s + "' is not NETNS_PATH:IFNAME");
  }
  return {s.substr(0, colon), s.substr(colon + 1)};
}

}  // namespace

int main(int argc, char** argv) {
  std::string a, b, spec, stats, ready;
  std::uint64_t seed = 1;
  CLI::App cli{"surgsim-netem: joins two network namespaces through TAP devices and forwards Ethernet frames with "
               "seeded delay, jitter, reordering and loss (a user-space netem)."};
  cli.add_option("--a", a, "First end: NETNS_PATH:IFNAME (e.g. /run/netns/surgsim-h-1:surg0)")->required();
  cli.add_option("--b", b, "Second end: NETNS_PATH:IFNAME")->required();
  cli.add_option("--impair", spec, "delay=5ms,jitter=2ms,loss=5%,reorder=0%[,seed=N] (both directions)");
  cli.add_option("--seed", seed, "Random seed")->capture_default_str();
  cli.add_option("--stats", stats, "JSON counters per direction, written on exit");
  cli.add_option("--ready", ready, "File created once both TAP devices exist");
  CLI11_PARSE(cli, argc, argv);

  try {
    const Impairment im = parse_impairment(spec, seed);
    const auto [ns_a, if_a] = split_end(a, "--a");
    const auto [ns_b, if_b] = split_end(b, "--b");
    const int fd_a = open_tap_in(ns_a, if_a);
    const int fd_b = open_tap_in(ns_b, if_b);
    prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0);
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);

    Direction ab, ba;
    ab.name = "a_to_b", ab.in = fd_a, ab.out = fd_b, ab.im = im, ab.rng.seed(seed * 2 + 0);
    ba.name = "b_to_a", ba.in = fd_b, ba.out = fd_a, ba.im = im, ba.rng.seed(seed * 2 + 1);
    if (!ready.empty()) std::ofstream(ready) << "ready\n";
    std::cerr << "surgsim-netem: " << if_a << " <-> " << if_b << ": delay " << im.delay_s * 1e3 << " ms, jitter +-"
              << im.jitter_s * 1e3 << " ms, loss " << im.loss * 100 << " %, reorder " << im.reorder * 100
              << " %, seed " << seed << "\n";

    std::vector<unsigned char> buf(65536);
    pollfd fds[2] = {{fd_a, POLLIN, 0}, {fd_b, POLLIN, 0}};
    while (!g_stop) {
      // Sleep until a TAP has a frame or the next delayed frame is due.
      std::uint64_t next = UINT64_MAX;
      if (!ab.queue.empty()) next = std::min(next, ab.queue.top().due_ns);
      if (!ba.queue.empty()) next = std::min(next, ba.queue.top().due_ns);
      const std::uint64_t now = surgsim::core::monotonic_ns();
      const std::uint64_t wait = next == UINT64_MAX ? 200000000ull : (next > now ? next - now : 0);
      timespec ts{static_cast<time_t>(wait / 1000000000ull), static_cast<long>(wait % 1000000000ull)};
      const int r = ::ppoll(fds, 2, &ts, nullptr);
      if (r < 0 && errno != EINTR) throw std::runtime_error(std::string("ppoll: ") + std::strerror(errno));
      if (r > 0) {
        if (fds[0].revents & POLLIN) ab.read_all(buf);
        if (fds[1].revents & POLLIN) ba.read_all(buf);
        if ((fds[0].revents | fds[1].revents) & (POLLERR | POLLHUP | POLLNVAL)) break;  // a namespace went away
      }
      const std::uint64_t t = surgsim::core::monotonic_ns();
      ab.send_due(t);
      ba.send_due(t);
    }
    nlohmann::json j;
    j["seed"] = seed;
    j["impairment"] = {{"delay_ms", im.delay_s * 1e3}, {"jitter_ms", im.jitter_s * 1e3}, {"loss", im.loss},
                       {"reorder", im.reorder}};
    j[ab.name] = ab.stats();
    j[ba.name] = ba.stats();
    if (!stats.empty()) std::ofstream(stats) << j.dump(2) << "\n";
    std::cerr << "surgsim-netem: a->b " << ab.received << " frames, " << ab.dropped << " dropped, " << ab.reordered
              << " reordered; b->a " << ba.received << " frames, " << ba.dropped << " dropped, " << ba.reordered
              << " reordered\n";
    ::close(fd_a);
    ::close(fd_b);
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "surgsim-netem: " << e.what() << "\n";
    return 1;
  }
}
