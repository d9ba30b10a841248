#include "mesh/geometry.h"

#include <gtest/gtest.h>

using namespace surgsim::mesh;

namespace surgsim {
namespace {

const Eigen::Vector3d kA(0, 0, 0), kB(1, 0, 0), kC(0, 1, 0);

TEST(SegmentTriangle, CrossingGivesParameterAndBarycentrics) {
  double s = -1;
  Eigen::Vector3d bary;
  ASSERT_TRUE(segment_triangle({0.25, 0.25, 1}, {0.25, 0.25, -1}, kA, kB, kC, s, bary));
  EXPECT_NEAR(s, 0.5, 1e-15);
  EXPECT_NEAR(bary.sum(), 1.0, 1e-15);
  const Eigen::Vector3d p = bary[0] * kA + bary[1] * kB + bary[2] * kC;
  EXPECT_TRUE(p.isApprox(Eigen::Vector3d(0.25, 0.25, 0), 1e-14));
}

TEST(SegmentTriangle, MissesOutsideShortAndParallel) {
  double s = 0;
  Eigen::Vector3d bary;
  EXPECT_FALSE(segment_triangle({0.8, 0.8, 1}, {0.8, 0.8, -1}, kA, kB, kC, s, bary));   // beyond the hypotenuse
  EXPECT_FALSE(segment_triangle({0.2, 0.2, 1}, {0.2, 0.2, 0.5}, kA, kB, kC, s, bary));  // stops above the plane
  EXPECT_FALSE(segment_triangle({0.2, 0.2, 0}, {0.3, 0.2, 0}, kA, kB, kC, s, bary));    // in the plane
}

TEST(ClosestPointTriangle, EachVoronoiRegion) {
  Eigen::Vector3d bary;
  // Interior: straight down.
  EXPECT_TRUE(closest_point_triangle({0.2, 0.3, 2}, kA, kB, kC, bary).isApprox(Eigen::Vector3d(0.2, 0.3, 0)));
  EXPECT_NEAR(bary.sum(), 1.0, 1e-15);
  // Vertex regions.
  EXPECT_TRUE(closest_point_triangle({-1, -1, 0.5}, kA, kB, kC, bary).isApprox(kA));
  EXPECT_NEAR(bary[0], 1.0, 1e-15);
  EXPECT_TRUE(closest_point_triangle({2, -0.5, 0}, kA, kB, kC, bary).isApprox(kB));
  // Edge region (hypotenuse): the foot of the perpendicular.
  EXPECT_TRUE(closest_point_triangle({1, 1, 0}, kA, kB, kC, bary).isApprox(Eigen::Vector3d(0.5, 0.5, 0)));
  EXPECT_NEAR(bary[1], 0.5, 1e-15);
  EXPECT_NEAR(bary[2], 0.5, 1e-15);
}

}  // namespace
}  // namespace surgsim
