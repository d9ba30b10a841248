// The whole haptic tick (input, contacts, force, DDS publication, log) on the shipped liver scene.
#include "haptic_app.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>

#include "support/alloc_counter.h"

namespace surgsim {
namespace {

HapticOptions test_options() {
  setenv("SURGSIM_CONFIG_DIR", SURGSIM_TEST_CONFIG_DIR, 1);
  HapticOptions o;
  o.scene = "liver";
  o.speed = 0;  // max
  o.quiet = true;
  o.cache_dir = SURGSIM_TEST_CACHE_DIR;
  o.domain = 1 + static_cast<int>((getpid() * 13) % 200);
  o.rt_priority = 0;
  o.lock_memory = false;
  std::filesystem::create_directories(o.cache_dir);
  return o;
}

// Runs ticks 0..warm-1, then counts the allocations of the remaining ticks.
long allocations_once_warm(HapticApp& app, std::uint64_t warm) {
  for (std::uint64_t k = 0; k < warm; ++k) app.tick(k);
  test::AllocationCounter counter;
  for (std::uint64_t k = warm; k < app.total_ticks(); ++k) app.tick(k);
  return counter.count();
}

TEST(HapticApp, TickAllocatesNothingOnceWarm) {
  HapticOptions o = test_options();
  o.log = ::testing::TempDir() + "/haptic_app_alloc_log.csv";
  HapticApp app(o);
  // Warm up: first contact, first DDS sends, log buffer.
  const std::uint64_t warm = 500;  // the poke reaches the organ at about 1.2 s (tick 370 at 300 Hz)
  EXPECT_EQ(allocations_once_warm(app, warm), 0) << "ticks " << warm << ".." << app.total_ticks();
}

// The intestine scene: mass-spring step, probe force, ContactFrame, ForceFeedback and BodyState every tick.
TEST(HapticApp, IntestineTickAllocatesNothingOnceWarm) {
  HapticOptions o = test_options();
  o.scene = "intestine";
  o.duration = 3.0;  // the push reaches the folds at about 1.9 s
  o.log = ::testing::TempDir() + "/haptic_app_intestine_alloc_log.csv";
  HapticApp app(o);
  const std::uint64_t warm = 200;  // first DDS sends, first self-contacts while the folds fall
  EXPECT_EQ(allocations_once_warm(app, warm), 0) << "ticks " << warm << ".." << app.total_ticks();
}

}  // namespace
}  // namespace surgsim
