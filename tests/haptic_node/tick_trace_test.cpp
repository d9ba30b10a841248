// The --tick-trace rows and their CSV: a wake-up seconds late (beyond 32 bits of ns) or a negative lateness is written
// as it was, not wrapped; wall and CPU times beyond 32 bits are held at their largest value.
#include "tick_trace.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

namespace surgsim {
namespace {

// The CSV rows (header dropped), each split at its commas.
std::vector<std::vector<std::string>> written(const std::vector<TickTrace>& rows) {
  std::FILE* f = std::tmpfile();
  EXPECT_NE(f, nullptr);
  write_tick_trace(f, rows.data(), rows.size());
  std::rewind(f);
  std::string text;
  char buf[512];
  while (std::fgets(buf, sizeof buf, f) != nullptr) text += buf;
  std::fclose(f);
  std::vector<std::vector<std::string>> out;
  std::istringstream lines(text);
  std::string line;
  EXPECT_TRUE(std::getline(lines, line));
  EXPECT_EQ(line.rfind("tick,due_us,wake_late_us,tick_us,tick_cpu_us,misses,", 0), 0u) << line;
  while (std::getline(lines, line)) {
    std::istringstream fields(line);
    std::vector<std::string> f;
    for (std::string v; std::getline(fields, v, ',');) f.push_back(v);
    out.push_back(f);
  }
  return out;
}

TEST(TickTrace, ALateWakeUpOfSecondsIsWrittenAsItWas) {
  const std::vector<TickTrace> rows = {
      tick_trace_row(1'000'000, 250, 80'000, 70'000, 0),            // an ordinary tick
      tick_trace_row(2'000'000, 5'000'000'000, 90'000, 60'000, 1),  // woke 5 s late (the process was stopped)
      tick_trace_row(3'000'000, 4'294'967'296, 90'000, 60'000, 2),  // exactly 2^32 ns late
      tick_trace_row(4'000'000, -1'500, 90'000, 60'000, 2)};        // a negative lateness stays negative
  const auto csv = written(rows);
  ASSERT_EQ(csv.size(), 4u);
  EXPECT_EQ(csv[0][1], "1000.000");
  EXPECT_EQ(csv[0][2], "0.250");
  EXPECT_EQ(csv[1][2], "5000000.000");
  EXPECT_EQ(csv[2][2], "4294967.296");
  EXPECT_EQ(csv[3][2], "-1.500");
  EXPECT_EQ(csv[1][5], "1");
}

TEST(TickTrace, WallAndCpuTimesBeyond32BitsAreHeldAtTheirLargest) {
  const auto csv = written({tick_trace_row(0, 0, 6'000'000'000, 5'000'000'000, 0)});
  ASSERT_EQ(csv.size(), 1u);
  EXPECT_EQ(csv[0][3], "4294967.295");
  EXPECT_EQ(csv[0][4], "4294967.295");
}

}  // namespace
}  // namespace surgsim
