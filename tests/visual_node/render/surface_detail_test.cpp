// The procedural surface detail (render/surface_detail.h): deterministic value noise and the per-vertex tints made
// from it once at load.
#include "render/surface_detail.h"

#include <gtest/gtest.h>

#include <cmath>

namespace surgsim {
namespace {

// A 20 x 20 x 2 grid of points 5 mm apart (a patch of organ surface).
Eigen::MatrixX3f patch() {
  Eigen::MatrixX3f p(800, 3);
  for (int i = 0; i < 800; ++i) p.row(i) << 0.005f * (i % 20), 0.005f * ((i / 20) % 20), 0.005f * (i / 400);
  return p;
}

TEST(SurfaceDetail, ValueNoiseIsDeterministicInRangeSmoothAndSeeded) {
  float lo = 1, hi = 0, step = 0;
  int differ = 0;
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3f p(0.37f * i, -0.11f * i, 0.05f * i);
    const float v = value_noise(p);
    EXPECT_EQ(v, value_noise(p)) << "the same point, the same value";
    lo = std::min(lo, v);
    hi = std::max(hi, v);
    step = std::max(step, std::abs(value_noise(p + Eigen::Vector3f(1e-3f, 0, 0)) - v));
    differ += value_noise(p, 7u) != v ? 1 : 0;
  }
  EXPECT_GE(lo, 0.0f);
  EXPECT_LE(hi, 1.0f);
  EXPECT_GT(hi - lo, 0.7f) << "spans most of [0, 1]";
  EXPECT_LT(step, 0.01f) << "continuous: a thousandth of a cell moves it little";
  EXPECT_GT(differ, 1900) << "another seed, another field";
}

TEST(SurfaceDetail, TintVariesAboutOneWithinTheMottleAndStreaksDarken) {
  const Eigen::MatrixX3f p = patch();
  SurfaceDetail d;
  d.scale = 40.0f;
  d.mottle = 0.1f;
  d.hue = 0.0f;
  const Eigen::MatrixX3f t = surface_tint(p, d);
  ASSERT_EQ(t.rows(), p.rows());
  EXPECT_GE(t.minCoeff(), 0.9f - 1e-6f);
  EXPECT_LE(t.maxCoeff(), 1.1f + 1e-6f);
  EXPECT_GT(t.maxCoeff() - t.minCoeff(), 0.08f) << "mottled, not flat";
  EXPECT_TRUE(t.col(0).isApprox(t.col(1)) && t.col(0).isApprox(t.col(2))) << "no hue: a grey factor";
  EXPECT_TRUE(surface_tint(p, d) == t) << "deterministic";
  // Streaks: some vertices darker than the mottle allows, none brighter.
  d.streaks = 1.0f;
  d.streak_scale = 25.0f;
  const Eigen::MatrixX3f s = surface_tint(p, d);
  int darker = 0;
  for (Eigen::Index v = 0; v < s.rows(); ++v) {
    EXPECT_LE(s(v, 0), t(v, 0) + 1e-6f);
    darker += s(v, 1) < 0.9f * t(v, 1) ? 1 : 0;
  }
  EXPECT_GT(darker, 8);
  EXPECT_LT(darker, 400) << "thin streaks, not the whole surface";
}

TEST(SurfaceDetail, BlendTintMultipliesByTheFactorWhereWeighted) {
  Eigen::MatrixX3f t = Eigen::MatrixX3f::Constant(3, 3, 0.5f);
  Eigen::VectorXf w(3);
  w << 0.0f, 0.5f, 1.0f;
  blend_tint(t, w, Eigen::Vector3f(3.0f, 1.0f, 0.0f));
  EXPECT_TRUE(t.row(0).isApprox(Eigen::RowVector3f(0.5f, 0.5f, 0.5f)));
  EXPECT_TRUE(t.row(1).isApprox(Eigen::RowVector3f(1.0f, 0.5f, 0.25f)));
  EXPECT_TRUE(t.row(2).isApprox(Eigen::RowVector3f(1.5f, 0.5f, 0.0f)));
}

}  // namespace
}  // namespace surgsim
