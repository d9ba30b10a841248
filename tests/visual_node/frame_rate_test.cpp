// FrameRateMeter (visual_node/frame_rate.h): the frame rate the visual node reports in VisualStatus.fps, measured
// over a sliding window of the last second of frame completion times. Synthetic stamps: no clock involved.
#include "frame_rate.h"

#include <gtest/gtest.h>

#include <cstdint>

namespace surgsim {
namespace {

constexpr std::uint64_t kMs = 1'000'000;

TEST(FrameRateMeter, NothingBeforeTwoFrames) {
  FrameRateMeter m;
  EXPECT_EQ(m.fps(), 0.0);
  m.add(5 * kMs);
  EXPECT_EQ(m.fps(), 0.0);
  m.add(25 * kMs);
  EXPECT_DOUBLE_EQ(m.fps(), 50.0);  // one 20 ms interval
}

TEST(FrameRateMeter, SteadyRateIsMeasured) {
  for (const double hz : {7.0, 30.0, 60.0, 144.0, 1000.0}) {
    FrameRateMeter m;
    const double period_ns = 1e9 / hz;
    for (int i = 0; i < 5 * static_cast<int>(hz) + 3; ++i) m.add(static_cast<std::uint64_t>(1e9 + i * period_ns));
    EXPECT_NEAR(m.fps(), hz, 1e-6 * hz) << hz;
  }
}

TEST(FrameRateMeter, FollowsTheLastSecondOnly) {
  // 2 s at 100 fps, then rendering slows to 20 fps: after one second of the slow rate the old frames are gone.
  FrameRateMeter m;
  std::uint64_t t = 0;
  for (int i = 0; i < 200; ++i) m.add(t += 10 * kMs);
  EXPECT_NEAR(m.fps(), 100.0, 1e-9);
  for (int i = 0; i < 10; ++i) m.add(t += 50 * kMs);  // half a second slow: a mix
  EXPECT_LT(m.fps(), 100.0);
  EXPECT_GT(m.fps(), 20.0);
  for (int i = 0; i < 20; ++i) m.add(t += 50 * kMs);  // a full second slow
  EXPECT_NEAR(m.fps(), 20.0, 1e-9);
}

TEST(FrameRateMeter, AStallLongerThanTheWindowGivesTheNewestInterval) {
  FrameRateMeter m;
  std::uint64_t t = 0;
  for (int i = 0; i < 100; ++i) m.add(t += 10 * kMs);
  m.add(t += 4000 * kMs);  // a 4 s stall
  EXPECT_NEAR(m.fps(), 0.25, 1e-12);
}

TEST(FrameRateMeter, RatesAboveTheRingUseItsFrames) {
  // 10 kHz: the ring keeps the last kCapacity stamps (0.41 s), the rate is still exact.
  FrameRateMeter m;
  for (int i = 0; i < 3 * FrameRateMeter::kCapacity; ++i) m.add(static_cast<std::uint64_t>(i) * 100'000);
  EXPECT_NEAR(m.fps(), 10000.0, 1e-6);
  EXPECT_EQ(m.frames(), static_cast<std::uint64_t>(3 * FrameRateMeter::kCapacity));
}

TEST(FrameRateMeter, ShorterWindow) {
  FrameRateMeter m(0.1);
  std::uint64_t t = 0;
  for (int i = 0; i < 50; ++i) m.add(t += 10 * kMs);
  for (int i = 0; i < 4; ++i) m.add(t += 40 * kMs);  // 0.16 s at 25 fps: the 0.1 s window sees only those
  EXPECT_NEAR(m.fps(), 25.0, 1e-9);
}

}  // namespace
}  // namespace surgsim
