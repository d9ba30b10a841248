#include "render/render_scale.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>

#include "core/error.h"
#include "render/image.h"

namespace surgsim {
namespace {

RenderScaleParams params(double min_scale) {
  RenderScaleParams p;
  p.min_scale = min_scale;
  p.target_work_s = 0.020;
  return p;
}

/// A frame whose work is a fixed part and a part proportional to the pixels drawn (s^2), in seconds.
struct Plant {
  double fixed_s;
  double pixels_s;  // at full size
  double work(double scale) const { return fixed_s + pixels_s * scale * scale; }
};

TEST(RenderScale, OffStaysAtFullSize) {
  RenderScaleController c(params(1.0));
  EXPECT_FALSE(c.active());
  for (int i = 0; i < 100; ++i) EXPECT_EQ(c.update(0.2), 1.0);
  EXPECT_EQ(c.frames_scaled(), 0);
}

TEST(RenderScale, HoldsWhileTheWorkIsNearItsTarget) {
  RenderScaleController c(params(0.5));
  for (int i = 0; i < 200; ++i) c.update(i % 2 == 0 ? 0.022 : 0.018);  // within 20 ms x / 1.15
  EXPECT_EQ(c.scale(), 1.0);
  EXPECT_EQ(c.frames_scaled(), 0);
}

TEST(RenderScale, IgnoresWorkThatIsNotAPositiveNumber) {
  RenderScaleController c(params(0.5));
  for (double w : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(), 0.0, -0.01}) {
    EXPECT_EQ(c.update(w), 1.0);
  }
  EXPECT_EQ(c.frames(), 0);
}

// Closed loop on a frame whose cost is mostly pixels: under a load (28 ms at full size against a 20 ms target) the
// scale settles where the work is within the deadband and then holds still; when the load goes it returns to full
// size; under a load no scale can meet it stops at the floor, never below.
TEST(RenderScale, SettlesUnderALoadReturnsToFullSizeAndStopsAtItsFloor) {
  RenderScaleController c(params(0.5));
  const Plant loaded{0.004, 0.024};
  int settled_at = -1;
  double settled_scale = 0;
  for (int k = 0; k < 200; ++k) {
    const double before = c.scale();
    c.update(loaded.work(before));
    if (settled_at < 0 && c.scale() == before && k > 0) {
      settled_at = k;
      settled_scale = c.scale();
    }
  }
  const double work = loaded.work(c.scale());
  std::printf("loaded 28 ms at full size: settled at scale %.3f (work %.2f ms) after %d frames\n", c.scale(),
              work * 1e3, settled_at);
  EXPECT_GE(settled_at, 0);
  EXPECT_LE(settled_at, 30);
  EXPECT_EQ(c.scale(), settled_scale) << "held still once inside the deadband";
  EXPECT_LT(c.scale(), 1.0);
  EXPECT_LE(work, 0.020 * 1.15 + 1e-12);
  EXPECT_GE(work, 0.020 / 1.15 - 1e-12);

  const Plant light{0.004, 0.008};  // 12 ms at full size
  int full_at = -1;
  for (int k = 0; k < 200 && full_at < 0; ++k) {
    if (c.update(light.work(c.scale())) == 1.0) full_at = k;
  }
  std::printf("load gone: full size after %d frames\n", full_at);
  EXPECT_GE(full_at, 0);
  EXPECT_LE(full_at, 30);

  const Plant heavy{0.030, 0.060};  // over the target even at the floor
  for (int k = 0; k < 200; ++k) EXPECT_GE(c.update(heavy.work(c.scale())), 0.5);
  EXPECT_EQ(c.scale(), 0.5);
  EXPECT_EQ(c.min_seen(), 0.5);
  EXPECT_GT(c.frames_scaled(), 200);
}

// One slow frame alone (a preemption) moves the scale by at most a few percent: the error is smoothed.
TEST(RenderScale, OneSlowFrameMovesTheScaleLittle) {
  RenderScaleController c(params(0.25));
  for (int i = 0; i < 20; ++i) c.update(0.015);
  c.update(0.080);
  EXPECT_GT(c.scale(), 0.8);
  EXPECT_LT(c.scale(), 1.0);
}

TEST(RenderScale, RefusesParametersOutOfRange) {
  for (double m : {0.2, 1.5, std::numeric_limits<double>::quiet_NaN()}) {
    EXPECT_THROW(RenderScaleController{params(m)}, core::Error) << m;
  }
  RenderScaleParams p = params(0.5);
  p.target_work_s = 0;
  EXPECT_THROW(RenderScaleController{p}, core::Error);
  p = params(0.5);
  p.gain = 0;
  EXPECT_THROW(RenderScaleController{p}, core::Error);
  p = params(0.5);
  p.deadband = -0.1;
  EXPECT_THROW(RenderScaleController{p}, core::Error);
}

// resize_bilinear against values computed here: a linear ramp is reproduced exactly between the outer pixel
// centres (bilinear interpolation is exact on linear functions) and held constant beyond them.
TEST(ResizeBilinear, ReproducesALinearRampAndAConstant) {
  Image src;
  src.resize(8, 4);
  for (int y = 0; y < src.height; ++y) {
    for (int x = 0; x < src.width; ++x) {
      std::uint8_t* p = src.at(x, y);
      p[0] = static_cast<std::uint8_t>(20 * x + 10);  // along x
      p[1] = static_cast<std::uint8_t>(40 * y + 5);   // along y
      p[2] = 77;                                      // constant
    }
  }
  Image dst;
  resize_bilinear(src, 20, 9, dst);
  ASSERT_EQ(dst.width, 20);
  ASSERT_EQ(dst.height, 9);
  auto expected = [](int i, int from, int to, double slope, double offset) {
    double s = (i + 0.5) * from / to - 0.5;
    s = std::fmin(std::fmax(s, 0.0), from - 1.0);
    return slope * s + offset;
  };
  for (int y = 0; y < dst.height; ++y) {
    for (int x = 0; x < dst.width; ++x) {
      const std::uint8_t* p = dst.at(x, y);
      EXPECT_NEAR(p[0], expected(x, 8, 20, 20.0, 10.0), 0.51) << x << "," << y;
      EXPECT_NEAR(p[1], expected(y, 4, 9, 40.0, 5.0), 0.51) << x << "," << y;
      EXPECT_EQ(p[2], 77);
    }
  }
  Image same;
  resize_bilinear(src, 8, 4, same);
  EXPECT_TRUE(same.rgb == src.rgb) << "the same size copies";
  Image none;
  resize_bilinear(Image{}, 8, 4, none);
  EXPECT_TRUE(none.empty());
}

}  // namespace
}  // namespace surgsim
