// The rigid organs' generators: each consistently oriented (closed where it should be) with the area and volume of
// closed-form formulas (the polygonal prism, the box, the ellipsoid, the spherical cap, Pappus for the ribs).
#include "rigid/rigid_shapes.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

#include "mesh/tri_surface.h"
#include "rigid/rigid_surface.h"
#include "support/error_test_util.h"

namespace surgsim::rigid {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Unit normal of triangle f as given (counter-clockwise) and its centroid.
Eigen::Vector3d normal_of(const mesh::TriSurface& s, int f) {
  const Eigen::Vector3d a = s.vertices.row(s.tris(f, 0)).transpose(), b = s.vertices.row(s.tris(f, 1)).transpose(),
                        c = s.vertices.row(s.tris(f, 2)).transpose();
  return (b - a).cross(c - a).normalized();
}
Eigen::Vector3d centroid_of(const mesh::TriSurface& s, int f) {
  return (s.vertices.row(s.tris(f, 0)) + s.vertices.row(s.tris(f, 1)) + s.vertices.row(s.tris(f, 2))).transpose() / 3.0;
}

TEST(RigidShapes, PlanePatchIsAnOpenSquareFacingUp) {
  const mesh::TriSurface s = plane_patch(0.2, 0.1, 8);
  EXPECT_EQ(s.tris.rows(), 128);
  EXPECT_NEAR(mesh::tri_surface_area(s), 0.02, 1e-15);
  const mesh::TriSurfaceTopology t = mesh::tri_surface_topology(s);
  EXPECT_EQ(t.nonmanifold_edges, 0);
  EXPECT_EQ(t.boundary_edges, 32);
  for (int f = 0; f < s.tris.rows(); ++f) EXPECT_NEAR(normal_of(s, f).z(), 1.0, 1e-12);
  EXPECT_NO_THROW(RigidSurface(s, false, "patch"));
}

TEST(RigidShapes, BoxIsClosedWithTheBoxsAreaAndVolume) {
  const Eigen::Vector3d h(0.03, 0.02, 0.01);
  const mesh::TriSurface s = box_surface(h, 4);
  EXPECT_NO_THROW(mesh::check_closed_surface(s, "box"));
  EXPECT_EQ(mesh::tri_surface_topology(s).euler, 2);
  EXPECT_NEAR(mesh::tri_surface_area(s), 8 * (h.x() * h.y() + h.y() * h.z() + h.z() * h.x()), 1e-15);
  EXPECT_NEAR(mesh::tri_surface_volume(s), 8 * h.prod(), 1e-17);
}

TEST(RigidShapes, TubeIsThePrismOfItsPolygon) {
  const double r = 0.01, length = 0.1;
  const int n = 32;
  const double side = 2 * r * std::sin(kPi / n), polygon = 0.5 * n * r * r * std::sin(2 * kPi / n);
  const mesh::TriSurface capped = tube_surface(r, length, n, 5, true);
  EXPECT_NO_THROW(mesh::check_closed_surface(capped, "tube"));
  EXPECT_NEAR(mesh::tri_surface_area(capped), n * side * length + 2 * polygon, 1e-14);
  EXPECT_NEAR(mesh::tri_surface_volume(capped), polygon * length, 1e-16);
  const mesh::TriSurface open = tube_surface(r, length, n, 5, false);
  EXPECT_EQ(mesh::tri_surface_topology(open).boundary_edges, 2 * n);
  EXPECT_EQ(mesh::tri_surface_topology(open).nonmanifold_edges, 0);
  EXPECT_NEAR(mesh::tri_surface_area(open), n * side * length, 1e-14);
  for (int f = 0; f < open.tris.rows(); ++f) {  // outward: along the radial direction of its centroid
    Eigen::Vector3d radial = centroid_of(open, f);
    radial.z() = 0;
    EXPECT_GT(normal_of(open, f).dot(radial.normalized()), 0.99);
  }
  EXPECT_NO_THROW(RigidSurface(open, false, "open tube"));
}

TEST(RigidShapes, ClosedEllipsoidHasTheEllipsoidsVolume) {
  const Eigen::Vector3d radii(0.1, 0.08, 0.06);
  const double exact = 4.0 / 3.0 * kPi * radii.prod();
  const mesh::TriSurface coarse = ellipsoid_shell(radii, 32, 16, -1);
  const mesh::TriSurface fine = ellipsoid_shell(radii, 128, 64, -1);
  EXPECT_NO_THROW(mesh::check_closed_surface(fine, "ellipsoid"));
  const double coarse_error = std::abs(mesh::tri_surface_volume(coarse) / exact - 1);
  const double fine_error = std::abs(mesh::tri_surface_volume(fine) / exact - 1);
  std::cout << "ellipsoid volume error: 32x16 " << 100 * coarse_error << " %, 128x64 " << 100 * fine_error << " %\n";
  EXPECT_LT(fine_error, 0.005);
  EXPECT_LT(fine_error, coarse_error / 8);  // second order in the segment size
}

TEST(RigidShapes, DomeIsAnOpenSphericalCapFacingOut) {
  const double radius = 0.15, z_min = -0.2;
  const mesh::TriSurface s = ellipsoid_shell(Eigen::Vector3d::Constant(radius), 256, 128, z_min);
  const mesh::TriSurfaceTopology t = mesh::tri_surface_topology(s);
  EXPECT_EQ(t.boundary_edges, 256);
  EXPECT_EQ(t.nonmanifold_edges, 0);
  const double cap = 2 * kPi * radius * radius * (1 - z_min);  // 2 pi R h
  EXPECT_NEAR(mesh::tri_surface_area(s) / cap, 1.0, 0.002);
  EXPECT_NEAR(s.vertices.col(2).minCoeff(), z_min * radius, 1e-12);
  for (int f = 0; f < s.tris.rows(); ++f) EXPECT_GT(normal_of(s, f).dot(centroid_of(s, f).normalized()), 0.999);
  EXPECT_NO_THROW(RigidSurface(s, true, "dome"));
}

TEST(RigidShapes, RibsAreSeparateClosedArcsWithPappusVolume) {
  RibsSpec spec;
  const mesh::TriSurface s = ribs(spec);
  const mesh::TriSurfaceTopology t = mesh::tri_surface_topology(s);
  EXPECT_TRUE(t.closed_manifold());
  EXPECT_EQ(t.components, spec.count);
  // Pappus: the rib's cross-section (a regular polygon) swept along its arc.
  const double polygon = 0.5 * spec.segments * std::pow(spec.tube_radius, 2) * std::sin(2 * kPi / spec.segments);
  const double pappus = spec.count * polygon * spec.arc_radius * spec.arc_deg * kPi / 180;
  EXPECT_NEAR(mesh::tri_surface_volume(s) / pappus, 1.0, 0.002);
  EXPECT_NO_THROW(RigidSurface(s, false, "ribs"));
}

TEST(RigidShapes, PlacedMovesEveryVertexRigidly) {
  const mesh::TriSurface box = box_surface(Eigen::Vector3d(0.03, 0.02, 0.01), 2);
  const mesh::Placement p =
      mesh::Placement::from_euler_deg(Eigen::Vector3d(0.1, -0.2, 0.3), Eigen::Vector3d(30, 45, 60));
  const mesh::TriSurface moved = placed(box, p);
  ASSERT_EQ(moved.vertices.rows(), box.vertices.rows());
  for (int v = 0; v < box.vertices.rows(); ++v) {
    const Eigen::Vector3d expected = p.rotation * box.vertices.row(v).transpose() + p.translation;
    EXPECT_LT((moved.vertices.row(v).transpose() - expected).norm(), 1e-15);
  }
  EXPECT_EQ(moved.tris, box.tris);
  EXPECT_NEAR(mesh::tri_surface_volume(moved), mesh::tri_surface_volume(box), 1e-17);
}

TEST(RigidShapes, BadParametersAreRefusedNamingTheGenerator) {
  EXPECT_TRUE(test::contains(test::error_of([] { plane_patch(0.1, 0.1, 0); }), "plane_patch"));
  EXPECT_TRUE(test::contains(test::error_of([] { box_surface(Eigen::Vector3d(0.1, 0, 0.1), 2); }), "box_surface"));
  EXPECT_TRUE(test::contains(test::error_of([] { tube_surface(0.01, 0.1, 2, 1, true); }), "tube_surface"));
  EXPECT_TRUE(
      test::contains(test::error_of([] { ellipsoid_shell(Eigen::Vector3d::Ones(), 8, 8, 1.5); }), "ellipsoid_shell"));
  RibsSpec touching;
  touching.spacing = touching.tube_radius;
  EXPECT_TRUE(test::contains(test::error_of([&] { ribs(touching); }), "ribs"));
}

}  // namespace
}  // namespace surgsim::rigid
