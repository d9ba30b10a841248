// DDS domain ids reserved for a test across every process of the machine, so that tests running in parallel (ctest
// -j, two checkouts) never share a domain and see each other's traffic. Domain d is taken by holding an exclusive
// flock on /tmp/surgsim-test-domains/<d>.lock for as long as the test process lives (the descriptor is kept open and
// is inherited by the nodes the test spawns, so the domain stays taken while they run). The search starts at a value
// derived from the pid (tests starting together usually land on different domains at once) and takes the next free one
// in 1..200 (Fast DDS's port scheme stops near 232). tests/integration/web_support.py (private_domain) and
// tests/integration/domain.sh (surgsim_reserve_domain) take the same locks for the Python and shell tests.
#pragma once
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>

namespace surgsim::test {

constexpr int kTestDomainCount = 200;  // domains 1..200
inline const char* const kTestDomainDir = "/tmp/surgsim-test-domains";

/// One domain of 1..200, taken while this object lives: the lock of <dir>/<domain>.lock, held on a descriptor of its
/// own. flock locks belong to the open file description, so a second reservation in the same process conflicts with
/// the first like one of another process does.
class DomainReservation {
 public:
  /// Takes the first free domain from `start` on (wrapping within 1..200); `dir` (created mode 1777 when missing)
  /// holds the lock files. Throws std::runtime_error when every domain is taken or the directory cannot be used.
  explicit DomainReservation(int start, const std::string& dir = kTestDomainDir) {
    make_dir(dir);
    for (int i = 0; i < kTestDomainCount; ++i) {
      const int d = 1 + ((start - 1 + i) % kTestDomainCount + kTestDomainCount) % kTestDomainCount;
      fd_ = try_take(d, dir);
      if (fd_ >= 0) {
        domain_ = d;
        return;
      }
    }
    throw std::runtime_error("no free DDS test domain: all " + std::to_string(kTestDomainCount) + " (1.." +
                             std::to_string(kTestDomainCount) + ") are held by other processes (locks in " + dir +
                             "/<domain>.lock)");
  }
  ~DomainReservation() {
    if (fd_ >= 0) ::close(fd_);
  }
  DomainReservation(DomainReservation&& o) noexcept : fd_(std::exchange(o.fd_, -1)), domain_(o.domain_) {}
  DomainReservation& operator=(DomainReservation&&) = delete;
  DomainReservation(const DomainReservation&) = delete;
  DomainReservation& operator=(const DomainReservation&) = delete;

  int domain() const { return domain_; }

  /// The descriptor holding the lock of domain `d` in `dir`, or -1 when another open file description holds it.
  static int try_take(int d, const std::string& dir) {
    const std::string path = dir + "/" + std::to_string(d) + ".lock";
    // Read-only (flock needs no write access), without O_CREAT when the file exists: another user's lock file in the
    // sticky directory can then still be opened.
    int fd = ::open(path.c_str(), O_RDONLY);
    if (fd < 0 && errno == ENOENT) fd = ::open(path.c_str(), O_RDONLY | O_CREAT, 0666);
    if (fd < 0 && errno == EACCES) fd = ::open(path.c_str(), O_RDONLY);  // created meanwhile by another user
    if (fd < 0) throw std::runtime_error("cannot open " + path + ": " + std::strerror(errno));
    int rc;
    do {
      rc = ::flock(fd, LOCK_EX | LOCK_NB);
    } while (rc != 0 && errno == EINTR);
    if (rc == 0) return fd;
    const int err = errno;
    ::close(fd);
    if (err == EWOULDBLOCK) return -1;
    throw std::runtime_error("cannot lock " + path + ": " + std::strerror(err));
  }

 private:
  static void make_dir(const std::string& dir) {
    if (::mkdir(dir.c_str(), 01777) == 0) {
      ::chmod(dir.c_str(), 01777);  // mkdir's mode went through the umask
    } else if (errno != EEXIST) {
      throw std::runtime_error("cannot create " + dir + ": " + std::strerror(errno));
    }
  }

  int fd_ = -1;
  int domain_ = 0;
};

/// The domain of this process for `salt`: reserved at the first call (the search starting at 1 + (pid * 7 + salt) %
/// 200) and held until the process exits; later calls with the same salt return it again, and each other salt gets a
/// domain of its own.
inline int reserve_test_domain(int salt = 0) {
  static std::map<int, DomainReservation> held;
  auto it = held.find(salt);
  if (it == held.end()) {
    const int start = 1 + static_cast<int>((static_cast<long>(getpid()) * 7 + salt) % kTestDomainCount);
    it = held.emplace(salt, DomainReservation(start)).first;
  }
  return it->second.domain();
}

}  // namespace surgsim::test
