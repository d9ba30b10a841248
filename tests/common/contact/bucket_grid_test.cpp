#include "contact/bucket_grid.h"

#include <gtest/gtest.h>

#include <random>

#include "mesh/box_mesh.h"

using namespace surgsim::mesh;
using namespace surgsim::contact;

namespace surgsim {
namespace {

class CollisionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    mesh_ = make_cylinder_mesh(0.05, 0.10, 6, 8);
    validate_mesh(mesh_);
    surface_ = boundary_surface(mesh_);
  }
  TetMesh mesh_;
  SurfaceMesh surface_;
};

TEST_F(CollisionTest, GridAgreesWithBruteForceOnRandomSegments) {
  BucketGrid grid(mesh_, surface_);
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> pos(-0.07, 0.07), z(-0.02, 0.12), step(-0.02, 0.02);
  int hits = 0;
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3d p0(pos(rng), pos(rng), z(rng));
    const Eigen::Vector3d p1 = p0 + Eigen::Vector3d(step(rng), step(rng), step(rng));
    const SurfaceHit a = grid.segment_query(p0, p1);
    const SurfaceHit b = grid.segment_query_brute(p0, p1);
    ASSERT_EQ(a.hit, b.hit) << "segment " << i;
    if (a.hit) {
      ++hits;
      EXPECT_NEAR(a.s, b.s, 1e-12);
      EXPECT_NEAR((a.point - b.point).norm(), 0.0, 1e-12);
    }
  }
  EXPECT_GT(hits, 100);  // the sample exercises crossings, not only misses
}

TEST_F(CollisionTest, FastStabIsDetectedInOneStep) {
  BucketGrid grid(mesh_, surface_);
  // 20 cm in one tick: far more than a triangle (10 m/s at 50 Hz); the top face at z = 0.1 must be found first.
  const Eigen::Vector3d p0(0.01, 0.005, 0.20), p1(0.01, 0.005, 0.0);
  const SurfaceHit h = grid.segment_query(p0, p1);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.point.z(), 0.10, 1e-12);
  EXPECT_NEAR(h.bary.sum(), 1.0, 1e-12);
}

TEST_F(CollisionTest, LeavingTheSurfaceIsNotAHit) {
  BucketGrid grid(mesh_, surface_);
  const SurfaceHit h = grid.segment_query({0.0, 0.0, 0.09}, {0.0, 0.0, 0.12});
  EXPECT_FALSE(h.hit);
}

// Deformed positions: the whole surface moved down by 1 cm; the crossing follows it.
void shifted(const void* ctx, int node, Eigen::Vector3d& out) {
  const auto* mesh = static_cast<const TetMesh*>(ctx);
  out = mesh->nodes.row(node).transpose() + Eigen::Vector3d(0, 0, -0.01);
}

TEST_F(CollisionTest, UsesDeformedPositionsOfCandidates) {
  BucketGrid grid(mesh_, surface_);
  const SurfaceHit h = grid.segment_query({0.012, -0.007, 0.15}, {0.012, -0.007, 0.05}, &shifted, &mesh_);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.point.z(), 0.09, 1e-12);
}

TEST_F(CollisionTest, ProjectionOntoRestSurface) {
  BucketGrid grid(mesh_, surface_);
  const SurfaceProjection p = grid.project_rest({0.01, 0.0, 0.097});
  ASSERT_TRUE(p.found);
  EXPECT_NEAR(p.point.z(), 0.10, 1e-12);
  EXPECT_NEAR(p.distance, 0.003, 1e-12);
  EXPECT_NEAR(p.normal.z(), 1.0, 1e-12);
}

TEST_F(CollisionTest, ProjectionKeepsToTheFacingSide) {
  BucketGrid grid(mesh_, surface_);
  const Eigen::Vector3d deep(0.0, 0.0, 0.015);  // 15 mm above the bottom face, 85 mm under the top
  const SurfaceProjection any = grid.project_rest(deep, 4);
  ASSERT_TRUE(any.found);
  EXPECT_LT(any.normal.z(), -0.9) << "the closest face is the bottom";
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  const SurfaceProjection facing = grid.project_rest(deep, 4, &up);
  ASSERT_TRUE(facing.found);
  EXPECT_GT(facing.normal.dot(up), BucketGrid::kFacingCos) << "a face turned away from +z was chosen";
  EXPECT_GT(facing.distance, any.distance);
}

TEST_F(CollisionTest, NearestNodeMatchesBruteForce) {
  BucketGrid grid(mesh_, surface_);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> pos(-0.05, 0.05), z(0.0, 0.1);
  for (int i = 0; i < 200; ++i) {
    Eigen::Vector3d p(pos(rng), pos(rng), z(rng));
    // Points near the surface: push radially onto the lateral surface.
    const double r = std::hypot(p.x(), p.y());
    if (r > 1e-6) p.head<2>() *= 0.05 / r;
    const int a = grid.nearest_node(p);
    int b = -1;
    double best = 1e9;
    for (int n : surface_.nodes) {
      const double d = (mesh_.nodes.row(n).transpose() - p).norm();
      if (d < best) best = d, b = n;
    }
    ASSERT_GE(a, 0);
    EXPECT_NEAR((mesh_.nodes.row(a).transpose() - p).norm(), best, 1e-12) << i << " " << b;
  }
}

TEST(BarycentricWeights, InterpolatedPointMovesByExactlyD) {
  const Eigen::Vector3d bary(0.2, 0.5, 0.3);
  const Eigen::Vector3d alpha = barycentric_weights(bary);
  // Vertex v moves by alpha_v d; the point moves by sum_v k_v alpha_v d = d.
  EXPECT_NEAR(bary.dot(alpha), 1.0, 1e-15);
  EXPECT_NEAR(alpha[1], 0.5 / (0.04 + 0.25 + 0.09), 1e-15);
}

}  // namespace
}  // namespace surgsim
