#include "async_writer.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

#include "support/alloc_counter.h"

namespace surgsim {
namespace {

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(AsyncLineWriter, EveryLineArrivesInOrder) {
  const std::string path = ::testing::TempDir() + "/async_writer_order.txt";
  std::FILE* f = std::fopen(path.c_str(), "w");
  ASSERT_NE(f, nullptr);
  std::string expected;
  {
    AsyncLineWriter w(f, /*wait_when_full=*/true, /*slots=*/256);
    for (int i = 0; i < 20000; ++i) {
      char* line = w.begin_line();
      ASSERT_NE(line, nullptr);
      const int n = std::snprintf(line, w.slot_bytes(), "%d\n", i);
      w.commit_line(static_cast<std::size_t>(n));
      expected += std::to_string(i) + "\n";
    }
    w.finish();
    EXPECT_EQ(w.dropped(), 0u);
  }
  std::fclose(f);
  EXPECT_EQ(slurp(path), expected);
}

TEST(AsyncLineWriter, FullRingDropsAndCountsWithoutBlockingOrAllocating) {
  const std::string path = ::testing::TempDir() + "/async_writer_full.txt";
  std::FILE* f = std::fopen(path.c_str(), "w");
  ASSERT_NE(f, nullptr);
  {
    // A writer that drains only every 10 s: the 8 slots fill at once and further lines are dropped.
    AsyncLineWriter w(f, /*wait_when_full=*/false, /*slots=*/8, /*slot_bytes=*/32, /*flush_ms=*/10000);
    long allocations = 0;
    int taken = 0;
    {
      test::AllocationCounter counter;
      for (int i = 0; i < 100; ++i) {
        if (char* line = w.begin_line()) {
          std::memcpy(line, "x\n", 2);
          w.commit_line(2);
          ++taken;
        }
      }
      allocations = counter.count();
    }
    EXPECT_EQ(allocations, 0);
    EXPECT_GE(taken, 8);
    EXPECT_EQ(w.dropped(), static_cast<std::uint64_t>(100 - taken));
  }  // the destructor drains what was taken
  std::fclose(f);
  EXPECT_FALSE(slurp(path).empty());
}

}  // namespace
}  // namespace surgsim
