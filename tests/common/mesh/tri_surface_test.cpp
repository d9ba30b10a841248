// Tests for common/mesh/tri_surface.cpp: topology (open edges, non-manifold edges, pinched vertices, parts), enclosed
// volume and area, triangle quality, compaction, and each refusal of check_closed_surface.
#include "mesh/tri_surface.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim {
namespace {

// The unit cube's surface, 12 triangles counter-clockwise seen from outside. Corner i + 2j + 4k is at (i, j, k).
TriSurface unit_cube(const Eigen::Vector3d& offset = Eigen::Vector3d::Zero()) {
  TriSurface s;
  s.vertices.resize(8, 3);
  for (int c = 0; c < 8; ++c) s.vertices.row(c) = Eigen::Vector3d(c & 1, (c >> 1) & 1, (c >> 2) & 1) + offset;
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  s.tris.resize(12, 3);
  for (int q = 0; q < 6; ++q) {
    s.tris.row(2 * q) << quads[q][0], quads[q][1], quads[q][2];
    s.tris.row(2 * q + 1) << quads[q][0], quads[q][2], quads[q][3];
  }
  return s;
}

// Two surfaces as one (b's vertices after a's).
TriSurface join(const TriSurface& a, const TriSurface& b) {
  TriSurface s;
  s.vertices.resize(a.vertices.rows() + b.vertices.rows(), 3);
  s.vertices << a.vertices, b.vertices;
  s.tris.resize(a.tris.rows() + b.tris.rows(), 3);
  s.tris << a.tris, (b.tris.array() + static_cast<int>(a.vertices.rows())).matrix();
  return s;
}

std::string closed_surface_error(const TriSurface& s) {
  try {
    check_closed_surface(s, "cube");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(TriSurface, CubeIsAClosedManifoldOfVolumeOneAndAreaSix) {
  const TriSurface s = unit_cube();
  const TriSurfaceTopology t = tri_surface_topology(s);
  EXPECT_EQ(t.vertices, 8);
  EXPECT_EQ(t.edges, 18);
  EXPECT_EQ(t.boundary_edges, 0);
  EXPECT_EQ(t.nonmanifold_edges, 0);
  EXPECT_EQ(t.nonmanifold_vertices, 0);
  EXPECT_EQ(t.components, 1);
  EXPECT_EQ(t.euler, 2);
  EXPECT_TRUE(t.closed_manifold());
  EXPECT_NEAR(tri_surface_volume(s), 1.0, 1e-15);
  EXPECT_NEAR(tri_surface_area(s), 6.0, 1e-15);
  // Right isosceles triangles: 4 sqrt(3) (1/2) / (1 + 1 + 2).
  EXPECT_NEAR(tri_surface_min_quality(s), std::sqrt(3.0) / 2.0, 1e-15);
  EXPECT_NO_THROW(check_closed_surface(s, "cube"));
}

TEST(TriSurface, VolumeDoesNotDependOnTheOriginAndChangesSignWhenFacingInward) {
  TriSurface s = unit_cube(Eigen::Vector3d(5.0, -3.0, 2.0));
  EXPECT_NEAR(tri_surface_volume(s), 1.0, 1e-12);
  s.tris.col(1).swap(s.tris.col(2));
  EXPECT_NEAR(tri_surface_volume(s), -1.0, 1e-12);
  EXPECT_NEAR(tri_surface_area(s), 6.0, 1e-12);
  EXPECT_TRUE(tri_surface_topology(s).closed_manifold());
  EXPECT_NE(closed_surface_error(s).find("cube: the surface encloses no positive volume (faces inward?)"),
            std::string::npos);
}

TEST(TriSurface, EquilateralTriangleHasQualityOneAndAFlatOneZero) {
  TriSurface s;
  s.vertices.resize(4, 3);
  s.vertices << 0, 0, 0, 1, 0, 0, 0.5, std::sqrt(3.0) / 2.0, 0, 2, 0, 0;
  s.tris.resize(1, 3);
  s.tris << 0, 1, 2;
  EXPECT_NEAR(tri_surface_min_quality(s), 1.0, 1e-15);
  s.tris.conservativeResize(2, 3);
  s.tris.row(1) << 0, 1, 3;  // three points on a line
  EXPECT_EQ(tri_surface_min_quality(s), 0.0);
}

TEST(TriSurface, OpenSurfaceCountsItsBoundaryEdges) {
  TriSurface s = unit_cube();
  s.tris.conservativeResize(11, 3);  // one triangle missing: a hole of three edges
  const TriSurfaceTopology t = tri_surface_topology(s);
  EXPECT_EQ(t.boundary_edges, 3);
  EXPECT_FALSE(t.closed_manifold());
  EXPECT_NE(closed_surface_error(s).find("cube: the surface is not a closed 2-manifold (3 open edges, 0 non-manifold "
                                         "or inconsistently oriented edges, 0 pinched vertices)"),
            std::string::npos);
}

TEST(TriSurface, InconsistentOrientationIsANonManifoldEdge) {
  TriSurface s = unit_cube();
  std::swap(s.tris(0, 1), s.tris(0, 2));  // one triangle flipped: its three edges run the same way as a neighbour's
  const TriSurfaceTopology t = tri_surface_topology(s);
  EXPECT_EQ(t.boundary_edges, 0);
  EXPECT_EQ(t.nonmanifold_edges, 3);
  EXPECT_FALSE(t.closed_manifold());
}

TEST(TriSurface, TwoCubesAreTwoPartsAndACornerSharedIsPinched) {
  const TriSurface apart = join(unit_cube(), unit_cube(Eigen::Vector3d(3, 0, 0)));
  const TriSurfaceTopology t = tri_surface_topology(apart);
  EXPECT_TRUE(t.closed_manifold());
  EXPECT_EQ(t.components, 2);
  EXPECT_EQ(t.euler, 4);
  EXPECT_NE(closed_surface_error(apart).find("cube: the surface has 2 separate parts (expected one)"),
            std::string::npos);

  // The second cube touching the first at corner 7 (1, 1, 1): make them share that vertex.
  TriSurface touching = join(unit_cube(), unit_cube(Eigen::Vector3d(1, 1, 1)));
  for (Eigen::Index f = 12; f < touching.tris.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (touching.tris(f, k) == 8) touching.tris(f, k) = 7;  // the second cube's corner 0 is the first's 7
  const TriSurfaceTopology p = tri_surface_topology(touching);
  EXPECT_EQ(p.vertices, 15);
  EXPECT_EQ(p.nonmanifold_vertices, 1);
  EXPECT_EQ(p.boundary_edges, 0);
  EXPECT_EQ(p.nonmanifold_edges, 0);
  EXPECT_FALSE(p.closed_manifold());
  EXPECT_NE(closed_surface_error(touching).find("1 pinched vertices"), std::string::npos);
}

TEST(TriSurface, CompactDropsUnusedVerticesAndKeepsTheOrder) {
  const TriSurface cube = unit_cube();
  TriSurface s;
  s.vertices.resize(10, 3);
  s.vertices.row(0) << 9, 9, 9;  // unused
  s.vertices.middleRows(1, 4) = cube.vertices.topRows(4);
  s.vertices.row(5) << -9, -9, -9;  // unused
  s.vertices.bottomRows(4) = cube.vertices.bottomRows(4);
  s.tris = cube.tris;
  for (Eigen::Index f = 0; f < s.tris.rows(); ++f)
    for (int k = 0; k < 3; ++k) s.tris(f, k) += s.tris(f, k) < 4 ? 1 : 2;
  compact_tri_surface(s);
  EXPECT_TRUE(s.vertices == cube.vertices);
  EXPECT_TRUE(s.tris == cube.tris);
}

TEST(TriSurface, CheckRefusesEmptyAndNonFiniteSurfaces) {
  TriSurface empty;
  EXPECT_NE(closed_surface_error(empty).find("cube: the surface has no triangles"), std::string::npos);
  TriSurface s = unit_cube();
  s.vertices(3, 1) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(closed_surface_error(s).find("cube: the surface has non-finite coordinates"), std::string::npos);
}

}  // namespace
}  // namespace surgsim
