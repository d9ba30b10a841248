#include "intestine/frame_rate_controller.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "core/error.h"

namespace surgsim::intestine {
namespace {

TEST(FrameRateControllerTest, FollowsEquationFifteen) {
  FrameRateParams p;
  p.target_hz = 60;
  FrameRateController ctl(p);
  const double eps0 = ctl.eps(), rho0 = ctl.rho();
  ctl.update(40);  // 20 Hz too slow
  EXPECT_DOUBLE_EQ(ctl.eps(), eps0 + 1e-4 * 20);
  EXPECT_DOUBLE_EQ(ctl.rho(), rho0 + 5 * (1e-4 * 20));
  EXPECT_EQ(ctl.levels_removed(), static_cast<int>(std::floor(ctl.rho())));
  EXPECT_EQ(ctl.lod(), p.lod_max - ctl.levels_removed());
}

// Synthetic load: frame time = a + b * polygons, polygons = P 2^lod (a tube of ~100 intervals).
struct Load {
  double a = 0.004;       // s, fixed cost
  double b = 2.5e-7;      // s per triangle
  double polygons(int lod) const { return 800.0 * std::pow(2.0, lod); }
  double fps(int lod) const { return 1.0 / (a + b * polygons(lod)); }
};

TEST(FrameRateControllerTest, ConvergesToTheTargetUnderASyntheticLoad) {
  const Load load;
  for (double target : {100.0, 150.0, 200.0}) {
    FrameRateParams p;
    p.target_hz = target;
    p.initial_lod = 0;
    FrameRateController ctl(p);
    // The finest level that still meets the target, and the next one.
    int best = 0;
    for (int l = 0; l <= p.lod_max; ++l) {
      if (load.fps(l) >= target) best = l;
    }
    double sum = 0;
    int count = 0, below = 0, above = 0;
    for (int k = 0; k < 20000; ++k) {
      const double f = load.fps(ctl.lod());
      if (k >= 10000) {
        sum += f;
        ++count;
        below += ctl.lod() < best;
        above += ctl.lod() > best + 1;
      }
      ctl.update(f);
    }
    // Settled: the LOD only alternates between the two levels around the target; their mean rate is the target.
    EXPECT_EQ(below, 0) << target;
    EXPECT_EQ(above, 0) << target;
    EXPECT_NEAR(sum / count, target, 0.02 * target) << "target " << target << " Hz";
  }
}

TEST(FrameRateControllerTest, ClampsWithoutWindUp) {
  const Load load;
  FrameRateParams p;
  p.target_hz = 500;  // unreachable: pinned at the coarsest level
  FrameRateController ctl(p);
  for (int k = 0; k < 5000; ++k) ctl.update(load.fps(ctl.lod()));
  EXPECT_EQ(ctl.lod(), p.lod_min);
  EXPECT_LT(ctl.rho(), p.lod_max - p.lod_min + 1);
  // The load lightens a lot (fps x 20): detail comes back within a bounded number of frames, not after unwinding
  // thousands of frames of accumulated error.
  int frames = 0;
  while (ctl.lod() < p.lod_max && frames < 2000) {
    ctl.update(20 * load.fps(ctl.lod()));
    ++frames;
  }
  EXPECT_EQ(ctl.lod(), p.lod_max);
  EXPECT_LT(frames, 1000);
}

TEST(FrameRateControllerTest, IgnoresBadMeasurementsAndRejectsBadParameters) {
  FrameRateController ctl(FrameRateParams{});
  const int lod = ctl.lod();
  const double rho = ctl.rho();
  EXPECT_EQ(ctl.update(std::numeric_limits<double>::quiet_NaN()), lod);
  EXPECT_EQ(ctl.update(0), lod);
  EXPECT_EQ(ctl.update_from_frame_time(-1), lod);
  EXPECT_EQ(ctl.rho(), rho);
  ctl.update_from_frame_time(0.1);  // 10 Hz against 50 Hz: rho rises
  EXPECT_GT(ctl.rho(), rho);
  FrameRateParams bad;
  bad.target_hz = 0;
  EXPECT_THROW(FrameRateController{bad}, Error);
  bad = FrameRateParams{};
  bad.lod_min = 4;
  bad.lod_max = 2;
  EXPECT_THROW(FrameRateController{bad}, Error);
}

}  // namespace
}  // namespace surgsim::intestine
