#include "tool/blade.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>

namespace surgsim::tool {
namespace {

ToolSpec scissors() {
  ToolSpec spec;
  spec.trocar = {0, 0, 0.2};
  spec.axis = {0, 0, -1};
  spec.jaw_length = 0.02;
  return spec;
}

Pose5 pose(double jaw, double insertion = 0.1) {
  Pose5 p;
  p.insertion = insertion;
  p.pitch = 0.2;
  p.yaw = -0.1;
  p.roll = 0.4;
  p.jaw = jaw;
  return p;
}

// Closing from 60 degrees in n steps with the pivot still: the swept triangles lie in the jaw plane and add up to the
// sector the blade tips draw, theta L^2 / 2 (the chords fall short of the arcs by O(1 / n^2)); each blade sweeps its
// own half.
TEST(BladeSweep, AClosureSweepsTheSectorOfTheJawPlane) {
  const ToolSpec spec = scissors();
  const double theta = M_PI / 3, sector = 0.5 * theta * spec.jaw_length * spec.jaw_length;
  for (int n : {4, 16, 64}) {
    double area = 0, off_plane = 0;
    for (int k = 0; k < n; ++k) {
      const ToolGeometry a = tool_geometry(spec, pose(theta * (n - k) / n));
      const ToolGeometry b = tool_geometry(spec, pose(theta * (n - k - 1) / n));
      const BladeSweep s = blade_sweep(a, theta * (n - k) / n, b, theta * (n - k - 1) / n);
      EXPECT_EQ(s.count, 2) << "one sliver per blade when the pivot holds";
      area += s.area();
      const Eigen::Vector3d normal = a.direction.cross(a.jaw_normal).normalized();
      for (int i = 0; i < s.count; ++i) {
        for (const Eigen::Vector3d& p : s.triangles[static_cast<std::size_t>(i)].p) {
          off_plane = std::max(off_plane, std::abs(normal.dot(p - a.tip)));
        }
      }
    }
    // 2 blades x n slivers, each the triangle (pivot, tip before, tip after) of half-angle step theta / (2 n)
    const double slivers = n * spec.jaw_length * spec.jaw_length * std::sin(theta / (2.0 * n));
    std::printf("closure in %d steps: swept %.6e m^2, sector %.6e m^2 (%.3f %% short)\n", n, area, sector,
                100 * (1 - area / sector));
    EXPECT_NEAR(area, slivers, 1e-15);
    EXPECT_LT(sector - area, sector * (theta * theta) / (12.0 * n * n) + 1e-15);  // theta^2 / (24 n^2) to leading order
    EXPECT_GE(sector - area, 0.0);
    EXPECT_LT(off_plane, 1e-15);
  }
}

// Moving while it closes: the pivot's path is swept too (the two triangles of each quadrilateral), so a closure while
// the instrument advances covers more than the sector.
TEST(BladeSweep, AdvancingWhileClosingSweepsTheQuadrilaterals) {
  const ToolSpec spec = scissors();
  const ToolGeometry a = tool_geometry(spec, pose(0.4, 0.10));
  const ToolGeometry b = tool_geometry(spec, pose(0.2, 0.11));
  const BladeSweep s = blade_sweep(a, 0.4, b, 0.2);
  EXPECT_EQ(s.count, 4);
  const ToolGeometry still = tool_geometry(spec, pose(0.2, 0.10));
  EXPECT_GT(s.area(), blade_sweep(a, 0.4, still, 0.2).area());
  for (int i = 0; i < s.count; ++i) EXPECT_GT(s.triangles[static_cast<std::size_t>(i)].area(), 1e-12);
}

TEST(BladeSweep, OpeningHoldingOrNonFiniteCutsNothing) {
  const ToolSpec spec = scissors();
  const ToolGeometry a = tool_geometry(spec, pose(0.2)), b = tool_geometry(spec, pose(0.4));
  EXPECT_EQ(blade_sweep(a, 0.2, b, 0.4).count, 0) << "opening";
  EXPECT_EQ(blade_sweep(a, 0.2, a, 0.2).count, 0) << "holding";
  const ToolGeometry closed_a = tool_geometry(spec, pose(0.0, 0.10)), closed_b = tool_geometry(spec, pose(0.0, 0.12));
  EXPECT_EQ(blade_sweep(closed_a, 0.0, closed_b, 0.0).count, 0) << "closed blades pushed in press, not cut";
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(blade_sweep(b, nan, a, 0.2).count, 0);
  ToolGeometry bad = a;
  bad.jaw_tips[1].x() = nan;
  EXPECT_EQ(blade_sweep(b, 0.4, bad, 0.2).count, 0);
}

}  // namespace
}  // namespace surgsim::tool
