#include "core/stats.h"

#include <gtest/gtest.h>

using namespace surgsim::core;

namespace surgsim {
namespace {

TEST(SampleRecorder, PercentilesOfKnownSamples) {
  SampleRecorder r(1000);
  for (int i = 1; i <= 100; ++i) r.add(i);
  const Percentiles p = r.summary();
  EXPECT_EQ(p.count, 100u);
  EXPECT_NEAR(p.p50, 50.0, 1.0);
  EXPECT_NEAR(p.p99, 99.0, 1.0);
  EXPECT_DOUBLE_EQ(p.max, 100.0);
  EXPECT_DOUBLE_EQ(p.mean, 50.5);
}

TEST(SampleRecorder, BeyondCapacityKeepsCountAndMax) {
  SampleRecorder r(10);
  for (int i = 0; i < 50; ++i) r.add(i);
  const Percentiles p = r.summary();
  EXPECT_EQ(p.count, 50u);
  EXPECT_DOUBLE_EQ(p.max, 49.0);
  EXPECT_LE(p.p99, 9.0);  // percentiles come from the stored prefix only
}

// A long-running thread's recorder keeps the newest window: percentiles of the last `capacity` samples, count, max
// and mean of all.
TEST(SampleRecorder, KeepNewestKeepsTheLastWindow) {
  SampleRecorder r(10, SampleRecorder::Keep::kNewest);
  for (int i = 0; i < 50; ++i) r.add(i);
  EXPECT_EQ(r.count(), 50u);
  EXPECT_DOUBLE_EQ(r.percentile(0.0), 40.0);
  EXPECT_DOUBLE_EQ(r.percentile(1.0), 49.0);
  EXPECT_DOUBLE_EQ(r.summary().p50, 45.0);  // 40..49: index round(0.5 * 9) = 5
  EXPECT_DOUBLE_EQ(r.summary().mean, 24.5);
}

TEST(SampleRecorder, PercentileOfTheFirstWindowAndOfNothing) {
  SampleRecorder r(10);
  EXPECT_EQ(r.percentile(0.5), 0.0);
  for (int i = 0; i < 50; ++i) r.add(i);
  EXPECT_DOUBLE_EQ(r.percentile(1.0), 9.0);
  EXPECT_DOUBLE_EQ(r.percentile(2.0), 9.0);  // q is clamped to [0, 1]
}

TEST(SampleRecorder, EmptyIsZero) {
  SampleRecorder r(4);
  const Percentiles p = r.summary();
  EXPECT_EQ(p.count, 0u);
  EXPECT_EQ(p.max, 0.0);
}

}  // namespace
}  // namespace surgsim
