// The CPU wake-up latency request: granted while held, withdrawn when the object goes.
#include "os/cpu_latency.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>

using namespace surgsim::os;

namespace surgsim {
namespace {

// Open descriptors of this process on /dev/cpu_dma_latency.
int open_requests() {
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator("/proc/self/fd")) {
    std::error_code ec;
    if (std::filesystem::read_symlink(e.path(), ec) == "/dev/cpu_dma_latency") ++n;
  }
  return n;
}

TEST(CpuLatencyRequest, NegativeAsksNothing) {
  const CpuLatencyRequest r(-1);
  EXPECT_FALSE(r.held());
  EXPECT_EQ(r.note(), "no CPU latency request (-1)");
  EXPECT_EQ(open_requests(), 0);
}

TEST(CpuLatencyRequest, ZeroIsGrantedWhileHeldAndWithdrawnAfter) {
  {
    const CpuLatencyRequest r(0);
    if (!r.held()) {
      EXPECT_NE(r.note().find("refused"), std::string::npos) << r.note();
      GTEST_SKIP() << r.note();
    }
    EXPECT_EQ(r.note(), "CPU wake-up latency <= 0 us (idle CPUs poll)");
    EXPECT_EQ(CpuLatencyRequest::current_us(), 0);  // the kernel grants the smallest request
    EXPECT_EQ(open_requests(), 1);
  }
  EXPECT_EQ(open_requests(), 0);  // closed: the kernel dropped the request
}

}  // namespace
}  // namespace surgsim
