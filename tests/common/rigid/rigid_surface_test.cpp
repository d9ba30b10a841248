// RigidSurface: its closest point against a brute force over every triangle (its own point-triangle distance, the
// side from a ray's crossings), the first contact of a moving sphere against sampling, the features touching a
// sphere, the errors on bad surfaces (each naming where), and queries that allocate nothing.
#include "rigid/rigid_surface.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <random>

#include "mesh/geometry.h"
#include "rigid/rigid_shapes.h"
#include "support/alloc_counter.h"
#include "support/error_test_util.h"

namespace surgsim::rigid {
namespace {

Eigen::Vector3d vertex(const mesh::TriSurface& s, int f, int k) { return s.vertices.row(s.tris(f, k)).transpose(); }

// Closest point on a segment, then on a triangle: the plane's projection when it falls inside, else the nearest of
// the three edges' (a different construction from Ericson's Voronoi regions the surface uses).
Eigen::Vector3d segment_closest(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const double s = std::clamp((p - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
  return a + s * (b - a);
}
Eigen::Vector3d triangle_closest(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                 const Eigen::Vector3d& c) {
  const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
  const Eigen::Vector3d q = p - n.dot(p - a) * n;
  if ((b - a).cross(q - a).dot(n) >= 0 && (c - b).cross(q - b).dot(n) >= 0 && (a - c).cross(q - c).dot(n) >= 0)
    return q;
  Eigen::Vector3d best = segment_closest(p, a, b);
  for (const Eigen::Vector3d& e : {segment_closest(p, b, c), segment_closest(p, c, a)})
    if ((p - e).squaredNorm() < (p - best).squaredNorm()) best = e;
  return best;
}
double brute_distance(const mesh::TriSurface& s, const Eigen::Vector3d& p) {
  double best = std::numeric_limits<double>::infinity();
  for (int f = 0; f < s.tris.rows(); ++f)
    best = std::min(best, (p - triangle_closest(p, vertex(s, f, 0), vertex(s, f, 1), vertex(s, f, 2))).norm());
  return best;
}
// Inside a closed surface: an odd number of crossings of a long ray in an arbitrary direction.
bool inside(const mesh::TriSurface& s, const Eigen::Vector3d& p) {
  const Eigen::Vector3d far = p + 10.0 * Eigen::Vector3d(0.5377, 0.3183, 0.7809).normalized();
  int crossings = 0;
  for (int f = 0; f < s.tris.rows(); ++f) {
    double t;
    Eigen::Vector3d bary;
    crossings += mesh::segment_triangle(p, far, vertex(s, f, 0), vertex(s, f, 1), vertex(s, f, 2), t, bary);
  }
  return crossings % 2 == 1;
}

void expect_closest_matches_brute_force(const mesh::TriSurface& s, bool cavity, bool closed) {
  const RigidSurface surface(s, cavity, "test");
  std::mt19937 rng(7);
  Eigen::AlignedBox3d box = surface.bounds();
  const Eigen::Vector3d margin = 0.2 * box.sizes() + Eigen::Vector3d::Constant(0.01);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 300; ++i) {
    const Eigen::Array3d at(u(rng), u(rng), u(rng));
    const Eigen::Vector3d p = ((box.min() - margin).array() + at * (box.sizes() + 2 * margin).array()).matrix();
    const ClosestPoint cp = surface.closest_point(p, 10.0);
    ASSERT_TRUE(cp.found);
    const double reference = brute_distance(s, p);
    EXPECT_NEAR(std::abs(cp.distance), reference, 1e-12) << "point " << p.transpose();
    EXPECT_NEAR((p - cp.point).norm(), reference, 1e-12);
    EXPECT_NEAR(cp.normal.norm(), 1.0, 1e-12);
    // The point is the barycentric combination of its triangle's corners, one of the input's triangles.
    Eigen::Vector3d at_bary = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) at_bary += cp.bary[k] * s.vertices.row(cp.corners[k]).transpose();
    EXPECT_LT((at_bary - cp.point).norm(), 1e-12);
    EXPECT_NEAR(cp.bary.sum(), 1.0, 1e-12);
    EXPECT_GE(cp.bary.minCoeff(), 0.0);
    Eigen::Vector3i input = s.tris.row(cp.triangle).transpose();
    Eigen::Vector3i stored = cp.corners;
    std::sort(input.data(), input.data() + 3);
    std::sort(stored.data(), stored.data() + 3);
    EXPECT_EQ(stored, input);
    if (reference > 1e-9)
      EXPECT_LT((cp.normal - (p - cp.point).normalized() * (cp.distance > 0 ? 1.0 : -1.0)).norm(), 1e-9);
    if (closed && reference > 1e-6) EXPECT_EQ(cp.distance > 0, inside(s, p) == cavity) << "point " << p.transpose();
    // Nothing within less than the distance, something within a little more.
    EXPECT_FALSE(surface.closest_point(p, 0.99 * reference).found);
    EXPECT_TRUE(surface.closest_point(p, 1.01 * reference + 1e-12).found);
  }
}

TEST(RigidSurface, ClosestPointMatchesBruteForceOnABox) {
  expect_closest_matches_brute_force(box_surface(Eigen::Vector3d(0.03, 0.02, 0.01), 3), false, true);
}
TEST(RigidSurface, ClosestPointMatchesBruteForceInsideABoxCavity) {
  expect_closest_matches_brute_force(box_surface(Eigen::Vector3d(0.03, 0.02, 0.01), 3), true, true);
}
TEST(RigidSurface, ClosestPointMatchesBruteForceOnAPlacedEllipsoid) {
  const mesh::Placement p =
      mesh::Placement::from_euler_deg(Eigen::Vector3d(0.1, 0.2, -0.1), Eigen::Vector3d(10, 20, 30));
  expect_closest_matches_brute_force(placed(ellipsoid_shell(Eigen::Vector3d(0.05, 0.04, 0.03), 24, 12, -1), p), false,
                                     true);
}
TEST(RigidSurface, ClosestPointMatchesBruteForceOnRibsAndADome) {
  RibsSpec spec;
  spec.count = 3;
  spec.segments = 8;
  spec.arc_segments = 12;
  expect_closest_matches_brute_force(ribs(spec), false, true);
  expect_closest_matches_brute_force(ellipsoid_shell(Eigen::Vector3d(0.1, 0.1, 0.08), 24, 12, -0.3), true, false);
}

TEST(RigidSurface, ClosestPointSignOnAnOpenPatchFollowsItsNormal) {
  const RigidSurface up(plane_patch(0.1, 0.1, 4), false, "patch");
  const ClosestPoint above = up.closest_point(Eigen::Vector3d(0.01, 0.02, 0.003), 1);
  EXPECT_NEAR(above.distance, 0.003, 1e-15);
  EXPECT_LT((above.normal - Eigen::Vector3d::UnitZ()).norm(), 1e-12);
  const ClosestPoint below = up.closest_point(Eigen::Vector3d(0.01, 0.02, -0.003), 1);
  EXPECT_NEAR(below.distance, -0.003, 1e-15);
  EXPECT_LT((below.normal - Eigen::Vector3d::UnitZ()).norm(), 1e-12);
  const RigidSurface down(plane_patch(0.1, 0.1, 4), true, "patch");
  EXPECT_NEAR(down.closest_point(Eigen::Vector3d(0.01, 0.02, 0.003), 1).distance, -0.003, 1e-15);
  EXPECT_EQ(up.triangle_count(), 32);
  EXPECT_NEAR(up.bounds().max().x(), 0.05, 1e-15);
}

// The first contact of a moving sphere: at it the sphere touches (brute-force distance = radius), before it never.
TEST(RigidSurface, SegmentHitIsTheFirstContactOfTheMovingSphere) {
  const mesh::TriSurface s = box_surface(Eigen::Vector3d(0.03, 0.02, 0.01), 2);
  const RigidSurface surface(s, false, "box");
  const double radius = 0.004;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.06, 0.06);
  int hits = 0;
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
    if (brute_distance(s, a) <= radius * 1.001) continue;
    const SegmentHit hit = surface.segment_hit(a, b, radius);
    for (int k = 0; k < 200; ++k) {
      const double t = (hit.hit ? hit.t : 1.0) * k / 200.0;
      EXPECT_GT(brute_distance(s, a + t * (b - a)), radius - 1e-12);
    }
    if (!hit.hit) {
      EXPECT_GT(brute_distance(s, b), radius - 1e-12);
      continue;
    }
    ++hits;
    EXPECT_NEAR(brute_distance(s, hit.centre), radius, 1e-12);
    EXPECT_LT((hit.centre - (a + hit.t * (b - a))).norm(), 1e-15);
  }
  EXPECT_GT(hits, 20);
  // Onto a face, an edge and a vertex of the box, with their exact first contacts.
  EXPECT_NEAR(surface.segment_hit(Eigen::Vector3d(0, 0, 0.05), Eigen::Vector3d::Zero(), radius).t,
              (0.05 - 0.01 - radius) / 0.05, 1e-14);
  const SegmentHit edge = surface.segment_hit(Eigen::Vector3d(0.05, 0.04, 0), Eigen::Vector3d(0.03, 0.02, 0), radius);
  EXPECT_NEAR(edge.t, 1 - radius / (0.02 * std::sqrt(2.0)), 1e-12);
  EXPECT_LT((edge.normal - Eigen::Vector3d(1, 1, 0).normalized()).norm(), 1e-9);
  const SegmentHit corner =
      surface.segment_hit(Eigen::Vector3d(0.05, 0.04, 0.03), Eigen::Vector3d(0.03, 0.02, 0.01), radius);
  EXPECT_NEAR(corner.t, 1 - radius / (0.02 * std::sqrt(3.0)), 1e-12);
  EXPECT_FALSE(surface.segment_hit(Eigen::Vector3d(0, 0, 0.05), Eigen::Vector3d(0, 0, 0.05), radius).hit);
}

TEST(RigidSurface, TouchingGivesOneNormalPerWallOfACavityCorner) {
  const RigidSurface room(box_surface(Eigen::Vector3d::Constant(0.05), 4), true, "room");
  std::array<Touch, 8> out;
  const double r = 0.003;
  EXPECT_EQ(room.touching(Eigen::Vector3d::Constant(0.05 - r), r * 1.001, out.data(), 8), 3);
  EXPECT_EQ(room.touching(Eigen::Vector3d(0.05 - r, 0.05 - r, 0), r * 1.001, out.data(), 8), 2);
  EXPECT_EQ(room.touching(Eigen::Vector3d(0.05 - r, 0.01, 0.003), r * 1.001, out.data(), 8), 1);
  EXPECT_LT((out[0].normal - Eigen::Vector3d(-1, 0, 0)).norm(), 1e-12);
  EXPECT_EQ(room.touching(Eigen::Vector3d::Zero(), r, out.data(), 8), 0);
  const RigidSurface solid(box_surface(Eigen::Vector3d::Constant(0.05), 4), false, "solid");
  EXPECT_EQ(solid.touching(Eigen::Vector3d::Constant(0.05 + r / 2), r, out.data(), 8), 1);  // the corner vertex
}

TEST(RigidSurface, QueriesAllocateNothing) {
  const RigidSurface surface(ellipsoid_shell(Eigen::Vector3d(0.1, 0.08, 0.06), 64, 32, -1), false, "ellipsoid");
  std::array<Touch, 8> out;
  double sum = 0;
  test::AllocationCounter counter;
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d p(0.001 * i, 0.02, 0.03);
    sum += surface.closest_point(p, 0.2).distance;
    sum += surface.segment_hit(p, Eigen::Vector3d::Zero(), 0.002).t;
    sum += surface.touching(p, 0.05, out.data(), 8);
  }
  EXPECT_EQ(counter.count(), 0);
  EXPECT_TRUE(std::isfinite(sum));
}

// Bad surfaces: each refused with a message naming where it came from.
mesh::TriSurface two_triangles() {
  mesh::TriSurface s;
  s.vertices.resize(4, 3);
  s.vertices << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  s.tris.resize(2, 3);
  s.tris << 0, 1, 2, 0, 2, 3;
  return s;
}

TEST(RigidSurface, BadSurfacesAreRefusedNamingWhere) {
  const std::string where = "scene.yaml: organs.wall";
  auto message = [&](const mesh::TriSurface& s) { return test::error_of([&] { RigidSurface(s, false, where); }); };
  EXPECT_NO_THROW(RigidSurface(two_triangles(), false, where));

  const std::string empty = message(mesh::TriSurface{});
  EXPECT_TRUE(test::contains(empty, where) && test::contains(empty, "no triangles")) << empty;

  mesh::TriSurface nan = two_triangles();
  nan.vertices(2, 1) = std::numeric_limits<double>::quiet_NaN();
  const std::string not_finite = message(nan);
  EXPECT_TRUE(test::contains(not_finite, where) && test::contains(not_finite, "not finite")) << not_finite;

  mesh::TriSurface flat = two_triangles();
  flat.vertices.row(2) << 0.5, 0, 0;  // on the edge 0-1
  const std::string degenerate = message(flat);
  EXPECT_TRUE(test::contains(degenerate, where) && test::contains(degenerate, "degenerate")) << degenerate;

  mesh::TriSurface flipped = box_surface(Eigen::Vector3d::Constant(0.01), 2);
  std::swap(flipped.tris(5, 1), flipped.tris(5, 2));
  const std::string orientation = message(flipped);
  EXPECT_TRUE(test::contains(orientation, where) && test::contains(orientation, "same direction") &&
              test::contains(orientation, "no side to push out to"))
      << orientation;

  mesh::TriSurface fin = two_triangles();  // a third triangle on the edge 0-2
  fin.vertices.conservativeResize(5, 3);
  fin.vertices.row(4) << 0.5, 0.5, 1;
  fin.tris.conservativeResize(3, 3);
  fin.tris.row(2) << 2, 0, 4;
  const std::string nonmanifold = message(fin);
  EXPECT_TRUE(test::contains(nonmanifold, where) && test::contains(nonmanifold, "non-manifold")) << nonmanifold;

  mesh::TriSurface out_of_range = two_triangles();
  out_of_range.tris(1, 2) = 9;
  EXPECT_TRUE(test::contains(message(out_of_range), where));
}

}  // namespace
}  // namespace surgsim::rigid
