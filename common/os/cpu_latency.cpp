#include "os/cpu_latency.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>

namespace surgsim::os {
namespace {
constexpr const char* kDevice = "/dev/cpu_dma_latency";
}

CpuLatencyRequest::CpuLatencyRequest(int max_us) {
  if (max_us < 0) {
    note_ = "no CPU latency request (" + std::to_string(max_us) + ")";
    return;
  }
  const int fd = open(kDevice, O_RDWR | O_CLOEXEC);
  if (fd < 0) {
    note_ = std::string("CPU latency request refused (") + kDevice + ": " + std::strerror(errno) + ")";
    return;
  }
  const auto value = static_cast<std::int32_t>(max_us);  // the device takes a binary 32-bit value
  if (write(fd, &value, sizeof value) != static_cast<ssize_t>(sizeof value)) {
    note_ = std::string("CPU latency request refused (") + kDevice + " write: " + std::strerror(errno) + ")";
    close(fd);
    return;
  }
  fd_ = fd;
  note_ = "CPU wake-up latency <= " + std::to_string(max_us) + " us" + (max_us == 0 ? " (idle CPUs poll)" : "");
}

CpuLatencyRequest::~CpuLatencyRequest() {
  if (fd_ >= 0) close(fd_);
}

long CpuLatencyRequest::current_us() {
  const int fd = open(kDevice, O_RDONLY | O_CLOEXEC);
  if (fd < 0) return -1;
  std::int32_t value = -1;
  const bool ok = read(fd, &value, sizeof value) == static_cast<ssize_t>(sizeof value);
  close(fd);
  return ok ? static_cast<long>(value) : -1;
}

}  // namespace surgsim::os
