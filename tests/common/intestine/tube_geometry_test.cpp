#include "intestine/tube_geometry.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "support/alloc_counter.h"
#include "core/error.h"
#include "intestine/intestine_model.h"
#include "support/intestine_test_util.h"

using namespace surgsim::core;
using namespace surgsim::intestine;

namespace surgsim::intestine {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::vector<double> flat(const std::vector<Eigen::Vector3d>& pts) {
  std::vector<double> f;
  for (const auto& p : pts) f.insert(f.end(), {p.x(), p.y(), p.z()});
  return f;
}

Eigen::Vector3d vertex(const TubeMesh& m, int i) {
  const auto k = static_cast<std::size_t>(3 * i);
  return {m.positions[k], m.positions[k + 1], m.positions[k + 2]};
}

// The worst violation (m, <= 0 is fine) of the cross-section condition over adjacent rings of a skinned tube:
// rings k and k+1 (centroids c1, c2, radii r1, r2 = farthest vertex, plane normals n1, n2 at angle theta) must
// satisfy d.n2 >= r1 sin(theta) and d.n1 >= r2 sin(theta), d = c2 - c1: the line where their planes meet passes
// outside both rings.
double worst_ring_violation(const TubeMesh& m, std::string* where = nullptr) {
  const int s = m.sides;
  std::vector<Eigen::Vector3d> c(static_cast<std::size_t>(m.ring_count)), n(c.size());
  std::vector<double> rad(c.size());
  for (int k = 0; k < m.ring_count; ++k) {
    Eigen::Vector3d g = Eigen::Vector3d::Zero(), nn = Eigen::Vector3d::Zero();
    for (int i = 0; i < s; ++i) g += vertex(m, k * s + i);
    g /= s;
    double r = 0;
    for (int i = 0; i < s; ++i) {
      nn += (vertex(m, k * s + i) - g).cross(vertex(m, k * s + (i + 1) % s) - g);  // Newell
      r = std::max(r, (vertex(m, k * s + i) - g).norm());
    }
    c[static_cast<std::size_t>(k)] = g;
    n[static_cast<std::size_t>(k)] = nn.normalized();
    rad[static_cast<std::size_t>(k)] = r;
  }
  double worst = -1e9;
  for (int k = 0; k + 1 < m.ring_count; ++k) {
    const auto i = static_cast<std::size_t>(k);
    const Eigen::Vector3d d = c[i + 1] - c[i];
    const double st = n[i].cross(n[i + 1]).norm();
    const double v = std::max(rad[i] * st - d.dot(n[i + 1]), rad[i + 1] * st - d.dot(n[i]));
    if (v > worst) {
      worst = v;
      if (where) *where = "rings " + std::to_string(k) + "/" + std::to_string(k + 1);
    }
  }
  return worst;
}

TEST(TubeGeometryTest, CardinalSplineInterpolatesWithContinuousTangents) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  std::vector<Eigen::Vector3d> p(8), m(8);
  for (int i = 0; i < 8; ++i) p[static_cast<std::size_t>(i)] = Eigen::Vector3d(0.04 * i + u(rng), u(rng), u(rng));
  cardinal_tangents(p.data(), 8, 0.3, m.data());
  for (int i = 0; i + 1 < 8; ++i) {
    const auto k = static_cast<std::size_t>(i);
    EXPECT_LT((hermite(p[k], p[k + 1], m[k], m[k + 1], 0) - p[k]).norm(), 1e-15);
    EXPECT_LT((hermite(p[k], p[k + 1], m[k], m[k + 1], 1) - p[k + 1]).norm(), 1e-15);
    EXPECT_LT((hermite_d1(p[k], p[k + 1], m[k], m[k + 1], 0) - m[k]).norm(), 1e-15);
    EXPECT_LT((hermite_d1(p[k], p[k + 1], m[k], m[k + 1], 1) - m[k + 1]).norm(), 1e-15);
    if (i > 0) {
      EXPECT_LT((m[k] - 0.35 * (p[k + 1] - p[k - 1])).norm(), 1e-15);  // (1 - c) / 2 = 0.35
    }
    // Derivatives against finite differences.
    const double t = 0.37, h = 1e-6;
    const Eigen::Vector3d fd1 =
        (hermite(p[k], p[k + 1], m[k], m[k + 1], t + h) - hermite(p[k], p[k + 1], m[k], m[k + 1], t - h)) / (2 * h);
    const Eigen::Vector3d fd2 = (hermite_d1(p[k], p[k + 1], m[k], m[k + 1], t + h) -
                                 hermite_d1(p[k], p[k + 1], m[k], m[k + 1], t - h)) / (2 * h);
    EXPECT_LT((fd1 - hermite_d1(p[k], p[k + 1], m[k], m[k + 1], t)).norm(), 1e-7);
    EXPECT_LT((fd2 - hermite_d2(p[k], p[k + 1], m[k], m[k + 1], t)).norm(), 1e-6);
  }
}

// A helix x = (R cos u, R sin u, P u): curvature and torsion constant; the rotation-minimizing frame turns against
// the Frenet frame at the rate -torsion per unit length.
TEST(TubeGeometryTest, RotationMinimizingFramesAreOrthonormalAndTwistMinimal) {
  const double R = 0.05, P = 0.02;
  const int n = 400;
  const double du = 4 * kPi / (n - 1);
  std::vector<Eigen::Vector3d> x(n), t(n), r(n), s(n);
  for (int i = 0; i < n; ++i) {
    const double u = i * du;
    x[static_cast<std::size_t>(i)] = Eigen::Vector3d(R * std::cos(u), R * std::sin(u), P * u);
    t[static_cast<std::size_t>(i)] = Eigen::Vector3d(-R * std::sin(u), R * std::cos(u), P).normalized();
  }
  const Eigen::Vector3d frenet0(-1, 0, 0);  // principal normal at u = 0 (towards the axis)
  rotation_minimizing_frames(x.data(), t.data(), n, frenet0, r.data(), s.data());
  const double speed = std::sqrt(R * R + P * P), torsion = P / (R * R + P * P);
  double worst_ortho = 0, worst_twist = 0;
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    worst_ortho = std::max({worst_ortho, std::abs(r[k].norm() - 1), std::abs(r[k].dot(t[k])),
                            (s[k] - t[k].cross(r[k])).norm()});
    // Angle of the RMF normal from the Frenet normal, about the tangent; analytic: -torsion * arc length.
    const double u = i * du;
    const Eigen::Vector3d fn(-std::cos(u), -std::sin(u), 0), fb = t[k].cross(fn);
    const double angle = std::atan2(r[k].dot(fb), r[k].dot(fn));
    double expected = -torsion * speed * u;
    expected = std::remainder(expected, 2 * kPi);
    worst_twist = std::max(worst_twist, std::abs(std::remainder(angle - expected, 2 * kPi)));
  }
  EXPECT_LT(worst_ortho, 1e-12);
  EXPECT_LT(worst_twist, 1e-4);
  // A planar curve: the normal started orthogonal to the plane stays there (no twist at all).
  for (int i = 0; i < n; ++i) {
    const double u = i * du;
    x[static_cast<std::size_t>(i)] = Eigen::Vector3d(R * std::cos(u) + 0.01 * u, R * std::sin(3 * u), 0);
    t[static_cast<std::size_t>(i)] =
        Eigen::Vector3d(-R * std::sin(u) + 0.01, 3 * R * std::cos(3 * u), 0).normalized();
  }
  rotation_minimizing_frames(x.data(), t.data(), n, Eigen::Vector3d::UnitZ(), r.data(), s.data());
  for (int i = 0; i < n; ++i) EXPECT_LT((r[static_cast<std::size_t>(i)] - Eigen::Vector3d::UnitZ()).norm(), 1e-12);
}

TEST(TubeGeometryTest, CurvatureIndicatorFlagsBendsAndAddsSamplesAroundTheMaximum) {
  TubeBuilder builder(TubeParams{}, 64);
  TubeMesh mesh = builder.make_mesh(0);
  // Straight: nothing flagged, one ring per point.
  std::vector<Eigen::Vector3d> line;
  for (int i = 0; i < 10; ++i) line.emplace_back(0.04 * i, 0, 0);
  ASSERT_TRUE(builder.build(flat(line).data(), 10, 0, mesh));
  EXPECT_EQ(builder.stats().flagged_segments, 0);
  EXPECT_EQ(builder.sample_count(), 10);
  for (int i = 0; i < 9; ++i) EXPECT_NEAR(builder.curvature_indicator(i), 0.0, 1e-12);
  // A 90 degree corner at point 5 (a wide one, 8 cm legs, so the tube can follow it): the segments around it are
  // flagged and get extra samples close to the corner.
  std::vector<Eigen::Vector3d> corner;
  for (int i = 0; i <= 5; ++i) corner.emplace_back(0.08 * i, 0, 0);
  for (int i = 1; i <= 4; ++i) corner.emplace_back(0.4, 0.08 * i, 0);
  ASSERT_TRUE(builder.build(flat(corner).data(), 10, 0, mesh));
  EXPECT_GT(builder.curvature_indicator(4), TubeParams{}.flag_turn);
  EXPECT_GT(builder.curvature_indicator(5), TubeParams{}.flag_turn);
  EXPECT_LT(builder.curvature_indicator(1), 1e-9);
  EXPECT_GE(builder.stats().flagged_segments, 2);
  EXPECT_GT(builder.stats().extra_samples, 0);
  int extra = 0;
  for (int k = 0; k < builder.sample_count(); ++k) {
    const TubeSample& s = builder.sample(k);
    if (!s.extra) continue;
    ++extra;
    EXPECT_TRUE(s.segment == 4 || s.segment == 5);
    EXPECT_LT((s.center - corner[5]).norm(), 0.08);  // clustered near the corner
  }
  EXPECT_GT(extra, 0);
  // The total turning through the corner is about 90 degrees.
  // The total turning through the corner: 90 degrees, plus the cardinal spline's overshoot on both sides.
  const double turning = builder.curvature_indicator(4) + builder.curvature_indicator(5);
  EXPECT_GT(turning, 0.5 * kPi);
  EXPECT_LT(turning, 0.75 * kPi);
}

// The ladder of levels: from 16 x 2 to 48 x 8 quads per interval, each level dearer than the one below it (1.2 to 2
// times its triangles), rings powers of two (the ring guard's subset), the mesh and the primitive sized by it.
TEST(TubeGeometryTest, LevelsOfDetailGrowFromARoundTubeToTheFinest) {
  TubeBuilder builder(TubeParams{}, 100);
  TubeMesh mesh = builder.make_mesh(kTubeMaxLod);
  const IntestineModel model(IntestineParams{});
  std::vector<double> pts(model.rest().data(), model.rest().data() + 3 * model.columns());
  int previous_triangles = 0;
  const int sides[] = {16, 24, 24, 32, 32, 40, 48}, rings[] = {2, 2, 4, 4, 8, 8, 8};
  for (int lod = 0; lod <= kTubeMaxLod; ++lod) {
    ASSERT_TRUE(builder.build(pts.data(), model.columns(), lod, mesh));
    const TubeLod l = tube_lod(lod);
    EXPECT_EQ(l.sides, sides[lod]);
    EXPECT_EQ(l.rings, rings[lod]);
    EXPECT_EQ(8 % l.rings, 0) << "rings among the guard's t = j / 8";
    const int triangles = mesh.body_index_count / 3;
    EXPECT_EQ(triangles, mesh.intervals * 2 * l.sides * l.rings);
    EXPECT_EQ(mesh.ring_count, mesh.intervals * l.rings + 1);
    EXPECT_EQ(mesh.body_vertex_count, mesh.ring_count * l.sides);
    // Plus two rounded caps of sides / 4 latitude steps.
    EXPECT_EQ(l.cap_rings, std::max(1, l.sides / 4));
    EXPECT_EQ(mesh.vertex_count, mesh.body_vertex_count + 2 * ((l.cap_rings - 1) * l.sides + 1));
    EXPECT_EQ(mesh.index_count, mesh.body_index_count + 2 * 3 * l.sides * (2 * l.cap_rings - 1));
    for (int i = 0; i < mesh.index_count; ++i) ASSERT_LT(mesh.indices[static_cast<std::size_t>(i)], static_cast<unsigned>(mesh.vertex_count));
    if (lod > 0) {
      EXPECT_GE(triangles, 6 * previous_triangles / 5) << "lod " << lod;
      EXPECT_LE(triangles, 2 * previous_triangles) << "lod " << lod;
    }
    previous_triangles = triangles;
    // The primitive of the LOD (GPU path) has (rings + 1) x sides vertices and 2 sides rings triangles, then the caps.
    const TubePrimitive& prim = builder.primitive(lod);
    EXPECT_EQ(prim.body_vertex_count, (l.rings + 1) * l.sides);
    EXPECT_EQ(prim.body_index_count, 3 * 2 * l.sides * l.rings);
    EXPECT_EQ(prim.cap_vertex_count, tube_cap_vertices(l));
    EXPECT_EQ(prim.cap_index_count, 3 * tube_cap_triangles(l));
    EXPECT_EQ(prim.vertices.size(), static_cast<std::size_t>(4 * (prim.body_vertex_count + 2 * prim.cap_vertex_count)));
    EXPECT_EQ(prim.indices.size(), static_cast<std::size_t>(prim.body_index_count + 2 * prim.cap_index_count));
  }
}

// The tube looks round at every level the frame-rate controller may choose, the coarsest included (live
// next to the haptic node it chooses 0-2). On the shipped rest shape, at every LOD: around every ring of the body
// adjacent vertices' normals are at most 26.5 degrees apart, so the interpolated shading turns smoothly across the
// sides, and the middle of every side edge lies within 2.5 % of the radius of the ring's circle, so the outline is a
// circle to under a pixel at the shipped camera; along the axis, between two consecutive rings, the tube's centre
// line turns by at most 55 degrees (where the ring guard cut a fold sharper than the tube). The paper's ladder failed
// at LOD 0: 4 sides, normals 90 degrees apart, flat faces 29 % inside the circle, the axis turning 75 degrees at once.
TEST(TubeGeometryTest, EveryLevelOfDetailIsRoundWithSmoothNormals) {
  const IntestineModel model(IntestineParams{});
  TubeParams params;
  TubeBuilder builder(params, model.columns());
  TubeMesh mesh = builder.make_mesh(kTubeMaxLod);
  for (int lod = 0; lod <= kTubeMaxLod; ++lod) {
    ASSERT_TRUE(builder.build(model.rest().data(), model.columns(), lod, mesh, TubeSkinning::kCpu));
    const int s = mesh.sides;
    double worst_normal_deg = 0, worst_flat = 0;
    for (int ring = 0; ring < mesh.ring_count; ++ring) {
      Eigen::Vector3d centre = Eigen::Vector3d::Zero();
      for (int i = 0; i < s; ++i) centre += vertex(mesh, ring * s + i);
      centre /= s;
      for (int i = 0; i < s; ++i) {
        const int a = ring * s + i, b = ring * s + (i + 1) % s;
        const Eigen::Vector3d na(mesh.normals[3 * a], mesh.normals[3 * a + 1], mesh.normals[3 * a + 2]);
        const Eigen::Vector3d nb(mesh.normals[3 * b], mesh.normals[3 * b + 1], mesh.normals[3 * b + 2]);
        worst_normal_deg = std::max(worst_normal_deg, std::acos(std::clamp(na.dot(nb), -1.0, 1.0)) * 180 / kPi);
        const double ra = (vertex(mesh, a) - centre).norm(), rb = (vertex(mesh, b) - centre).norm();
        const double mid = (0.5 * (vertex(mesh, a) + vertex(mesh, b)) - centre).norm();
        worst_flat = std::max(worst_flat, 1.0 - mid / (0.5 * (ra + rb)));
      }
    }
    double worst_turn_deg = 0;
    Eigen::Vector3d previous = Eigen::Vector3d::Zero();
    for (int ring = 1; ring < mesh.ring_count; ++ring) {
      Eigen::Vector3d c0 = Eigen::Vector3d::Zero(), c1 = Eigen::Vector3d::Zero();
      for (int i = 0; i < s; ++i) {
        c0 += vertex(mesh, (ring - 1) * s + i);
        c1 += vertex(mesh, ring * s + i);
      }
      const Eigen::Vector3d d = (c1 - c0).normalized();
      if (ring > 1) worst_turn_deg = std::max(worst_turn_deg, std::acos(std::clamp(d.dot(previous), -1.0, 1.0)) * 180 / kPi);
      previous = d;
    }
    std::printf("LOD %d (%d sides x %d rings): adjacent normals up to %.1f deg, sides %.2f %% inside the circle, axis "
                "turns up to %.1f deg between rings\n", lod, s, tube_lod(lod).rings, worst_normal_deg,
                100 * worst_flat, worst_turn_deg);
    EXPECT_LE(worst_normal_deg, 26.5) << "lod " << lod;
    EXPECT_LE(worst_flat, 0.025) << "lod " << lod;
    EXPECT_LE(worst_turn_deg, 55.0) << "lod " << lod;
  }
}

TEST(TubeGeometryTest, SkinningMatricesReproduceTheCpuTube) {
  TubeBuilder builder(TubeParams{}, 100);
  TubeMesh mesh = builder.make_mesh(3);
  const IntestineModel model(IntestineParams{});
  ASSERT_TRUE(builder.build(model.rest().data(), model.columns(), 3, mesh));
  const TubePrimitive& prim = builder.primitive(3);
  const int sides = prim.lod.sides, q = prim.lod.rings;
  double worst = 0;
  for (int k = 0; k < mesh.intervals; ++k) {
    const float* m = &mesh.skin[static_cast<std::size_t>(24 * k)];
    for (int j = 0; j < q; ++j) {
      for (int i = 0; i < sides; ++i) {
        const float* v = &prim.vertices[static_cast<std::size_t>(4 * (j * sides + i))];
        const Eigen::Vector4d local(v[0], v[1], v[2], 1);
        Eigen::Vector3d a, b;
        for (int row = 0; row < 3; ++row) {
          a[row] = m[4 * row] * local[0] + m[4 * row + 1] * local[1] + m[4 * row + 2] * local[2] + m[4 * row + 3];
          b[row] = m[12 + 4 * row] * local[0] + m[12 + 4 * row + 1] * local[1] + m[12 + 4 * row + 2] * local[2] +
                   m[12 + 4 * row + 3];
        }
        const double w = skin_weight(v[2]);
        const Eigen::Vector3d gpu = (1 - w) * a + w * b;  // the vertex shader's blend (z = 0 on the tube)
        worst = std::max(worst, (gpu - vertex(mesh, (k * q + j) * sides + i)).norm());
      }
    }
  }
  EXPECT_LT(worst, 1e-6);
  // Every vertex, caps included, by the full formula of the header (what the vertex shader computes): positions
  // and normals.
  double worst_position = 0, worst_normal = 0;
  const int nv = prim.body_vertex_count + 2 * prim.cap_vertex_count;
  for (int k = 0; k < mesh.intervals; ++k) {
    const Eigen::Map<const Eigen::Matrix<float, 3, 4, Eigen::RowMajor>> a(&mesh.skin[static_cast<std::size_t>(24 * k)]);
    const Eigen::Map<const Eigen::Matrix<float, 3, 4, Eigen::RowMajor>> b(&mesh.skin[static_cast<std::size_t>(24 * k + 12)]);
    for (int i = 0; i < nv; ++i) {
      const float* v = &prim.vertices[static_cast<std::size_t>(4 * i)];
      const bool start_cap = i >= prim.body_vertex_count && i < prim.body_vertex_count + prim.cap_vertex_count;
      const bool end_cap = i >= prim.body_vertex_count + prim.cap_vertex_count;
      if ((start_cap && k != 0) || (end_cap && k != mesh.intervals - 1)) continue;  // caps: first / last interval
      int target = 0;  // the CPU mesh's vertex
      if (start_cap || end_cap) {
        target = mesh.body_vertex_count + i - prim.body_vertex_count;
      } else {
        const int j = i / sides;
        if (j == q && k + 1 < mesh.intervals) continue;  // the next interval's first ring
        target = (k * q + j) * sides + i % sides;
      }
      const Eigen::Vector4d local(v[0], v[1], v[2], 1);
      const double w = skin_weight(v[2]);
      const Eigen::Matrix<double, 3, 4> ad = a.cast<double>(), bd = b.cast<double>();
      const Eigen::Vector3d ta = ad.col(2).normalized(), tb = bd.col(2).normalized();
      const Eigen::Vector3d p = (1 - w) * (ad * local + v[3] * ad.col(0).norm() * ta) +
                                w * (bd * local + v[3] * bd.col(0).norm() * tb);
      const Eigen::Vector3d n = ((1 - w) * (v[0] * ad.col(0).normalized() + v[1] * ad.col(1).normalized() + v[3] * ta) +
                                 w * (v[0] * bd.col(0).normalized() + v[1] * bd.col(1).normalized() + v[3] * tb))
                                    .normalized();
      const auto t3 = static_cast<std::size_t>(3 * target);
      worst_position = std::max(worst_position, (p - vertex(mesh, target)).norm());
      worst_normal = std::max(
          worst_normal, (n - Eigen::Vector3d(mesh.normals[t3], mesh.normals[t3 + 1], mesh.normals[t3 + 2])).norm());
    }
  }
  EXPECT_LT(worst_position, 1e-6);
  EXPECT_LT(worst_normal, 1e-5);
  EXPECT_DOUBLE_EQ(skin_weight(0), 0);
  EXPECT_DOUBLE_EQ(skin_weight(1), 1);
  EXPECT_DOUBLE_EQ(skin_weight(0.5), 0.5);
}

// The end caps close the tube at every LOD: every edge of the CPU mesh is shared by exactly two triangles, each
// directed edge appears once (one consistent winding), the winding agrees with the vertex normals, the enclosed
// volume is positive (normals outward) and close to a tube of the curve's length with two half-spheres.
TEST(TubeGeometryTest, EndCapsMakeTheTubeWatertightWithOutwardNormals) {
  const TubeParams tp;
  TubeBuilder builder(tp, 100);
  TubeMesh mesh = builder.make_mesh(kTubeMaxLod);
  const IntestineModel model(IntestineParams{});
  std::vector<Eigen::Vector3d> straight;
  for (int i = 0; i < 6; ++i) straight.emplace_back(0.05 * i, 0.0, 0.0);
  const std::vector<std::pair<std::string, std::vector<double>>> curves = {
      {"straight", flat(straight)},
      {"folded rest intestine", std::vector<double>(model.rest().data(), model.rest().data() + 3 * model.columns())}};
  for (const auto& [name, pts] : curves) {
    for (int lod = 0; lod <= kTubeMaxLod; ++lod) {
      builder.reset_frames();
      ASSERT_TRUE(builder.build(pts.data(), static_cast<int>(pts.size() / 3), lod, mesh)) << name;
      std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
      double volume = 0;
      int disagreeing = 0;
      for (int f = 0; f < mesh.index_count / 3; ++f) {
        const std::uint32_t* t = &mesh.indices[static_cast<std::size_t>(3 * f)];
        for (int e = 0; e < 3; ++e) ++directed[{t[e], t[(e + 1) % 3]}];
        const Eigen::Vector3d a = vertex(mesh, static_cast<int>(t[0])), b = vertex(mesh, static_cast<int>(t[1])),
                              c = vertex(mesh, static_cast<int>(t[2]));
        volume += a.dot(b.cross(c)) / 6;
        Eigen::Vector3d n = Eigen::Vector3d::Zero();
        for (int e = 0; e < 3; ++e) {
          const auto k = static_cast<std::size_t>(3 * t[e]);
          n += Eigen::Vector3d(mesh.normals[k], mesh.normals[k + 1], mesh.normals[k + 2]);
        }
        if ((b - a).cross(c - a).dot(n) <= 0) ++disagreeing;
      }
      int open = 0, bad_winding = 0;
      for (const auto& [edge, count] : directed) {
        if (count != 1) ++bad_winding;
        if (directed.count({edge.second, edge.first}) == 0) ++open;
      }
      EXPECT_EQ(open, 0) << name << " lod " << lod << ": edges in one triangle only";
      EXPECT_EQ(bad_winding, 0) << name << " lod " << lod << ": directed edges in more than one triangle";
      EXPECT_EQ(disagreeing, 0) << name << " lod " << lod << ": triangles wound against their normals";
      EXPECT_EQ(directed.size(), static_cast<std::size_t>(mesh.index_count)) << name;  // 3 per triangle, all distinct
      EXPECT_GT(volume, 0) << name << " lod " << lod;
      if (name == "straight" && lod == kTubeMaxLod) {
        const double r = tp.radius, expected = kPi * r * r * 0.25 + 4.0 / 3.0 * kPi * r * r * r;
        EXPECT_NEAR(volume, expected, 0.03 * expected);  // the polygons' shortfall at 32 sides is ~0.6 %
      }
    }
  }
  // The poles sit one radius beyond the end rings, along the tube's ends' tangents.
  const TubeSample &first = builder.sample(0), &last = builder.sample(builder.sample_count() - 1);
  const TubeLod l = tube_lod(kTubeMaxLod);
  const int cap = tube_cap_vertices(l);
  EXPECT_LT((vertex(mesh, mesh.body_vertex_count + cap - 1) - (first.center - first.radius * first.tangent)).norm(), 1e-6);
  EXPECT_LT((vertex(mesh, mesh.body_vertex_count + 2 * cap - 1) - (last.center + last.radius * last.tangent)).norm(), 1e-6);
}

// The test the issue names: at sharp folds the skinned tube has no self-intersecting cross-sections.
TEST(TubeGeometryTest, NoSelfIntersectingCrossSectionsAtSharpFolds) {
  std::vector<std::pair<std::string, std::vector<Eigen::Vector3d>>> shapes;
  // Hairpins whose legs are 6 cm apart, and 4 cm (the tubes touch: the tightest fold the collision response allows).
  for (double w : {0.06, 0.04}) {
    std::vector<Eigen::Vector3d> hairpin;
    for (int i = 0; i <= 5; ++i) hairpin.emplace_back(0.04 * i, 0, 0);
    hairpin.emplace_back(0.2 + 0.5 * w, 0.5 * w, 0);
    for (int i = 5; i >= 0; --i) hairpin.emplace_back(0.04 * i, w, 0);
    shapes.emplace_back("hairpin " + std::to_string(w), hairpin);
  }
  // A staircase of right angles, 4 cm steps.
  std::vector<Eigen::Vector3d> stairs;
  for (int i = 0; i < 12; ++i) stairs.emplace_back(0.04 * ((i + 1) / 2), 0.04 * (i / 2), 0);
  shapes.emplace_back("stairs", stairs);
  // A tight helix (radius 2 cm = the tube's).
  std::vector<Eigen::Vector3d> helix;
  for (int i = 0; i < 20; ++i) helix.emplace_back(0.02 * std::cos(1.7 * i), 0.02 * std::sin(1.7 * i), 0.012 * i);
  shapes.emplace_back("helix", helix);
  // Kinks sharper than the tube can follow (166 and 180 degrees) and a crumpled random walk.
  shapes.emplace_back("kink", std::vector<Eigen::Vector3d>{{0, 0, 0}, {0.04, 0, 0}, {0.08, 0, 0}, {0.04, 0.01, 0},
                                                           {0.0, 0.01, 0}, {0.04, 0.01, 0.0001}, {0.08, 0.02, 0}});
  std::mt19937 rng(5);
  std::normal_distribution<double> g(0, 1);
  std::vector<Eigen::Vector3d> walk{{0, 0, 0}};
  for (int i = 0; i < 60; ++i) walk.push_back(walk.back() + 0.04 * Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized());
  shapes.emplace_back("random walk", walk);
  // The simulated intestine after a second of the scripted run.
  const IntestineModel model(IntestineParams{});
  IntestineState state(model, 1);
  StepReport report;
  for (int s = 0; s < 1000; ++s) step(model, state, test::scripted_probe(s * 1e-3), 1e-3, report);
  std::vector<Eigen::Vector3d> gut;
  for (int c = 0; c < model.columns(); ++c) gut.push_back(state.x.col(c));
  shapes.emplace_back("simulated intestine", gut);
  shapes.emplace_back("rest intestine",
                      std::vector<Eigen::Vector3d>(gut.size(), Eigen::Vector3d::Zero()));
  for (int c = 0; c < model.columns(); ++c) shapes.back().second[static_cast<std::size_t>(c)] = model.rest().col(c);

  TubeBuilder builder(TubeParams{}, 128);
  TubeMesh mesh = builder.make_mesh(kTubeMaxLod);
  for (const auto& [name, pts] : shapes) {
    for (int lod = 0; lod <= kTubeMaxLod; ++lod) {
      builder.reset_frames();
      ASSERT_TRUE(builder.build(flat(pts).data(), static_cast<int>(pts.size()), lod, mesh)) << name;
      std::string where;
      const double v = worst_ring_violation(mesh, &where);
      EXPECT_LE(v, 1e-6) << name << " lod " << lod << " at " << where;
    }
  }
}

TEST(TubeGeometryTest, TubeKeepsItsRadiusAndFollowsThePoints) {
  const TubeParams tp;
  TubeBuilder builder(tp, 100);
  TubeMesh mesh = builder.make_mesh(4);
  const IntestineModel model(IntestineParams{});
  ASSERT_TRUE(builder.build(model.rest().data(), model.columns(), 4, mesh));
  const int s = mesh.sides;
  double rmin = 1, rmax = 0;
  for (int k = 0; k < mesh.ring_count; ++k) {
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    for (int i = 0; i < s; ++i) g += vertex(mesh, k * s + i);
    g /= s;
    double far = 0;
    for (int i = 0; i < s; ++i) far = std::max(far, (vertex(mesh, k * s + i) - g).norm());
    rmin = std::min(rmin, far);
    rmax = std::max(rmax, far);
  }
  EXPECT_LE(rmax, tp.radius * (1 + 1e-5));
  EXPECT_GE(rmin, tp.min_radius_fraction * tp.radius * 0.99);
  // Every input point is a ring centre (the guard cut no corner of the rest shape); only the crests' apexes, where
  // the folded curve bends tighter than the tube, are narrowed. Normals are unit.
  int original = 0, narrowed = 0;
  for (int k = 0; k < builder.sample_count(); ++k) {
    original += builder.sample(k).extra ? 0 : 1;
    narrowed += builder.sample(k).radius < tp.radius ? 1 : 0;
  }
  EXPECT_EQ(original, model.columns());
  EXPECT_EQ(narrowed, builder.stats().narrowed_rings);
  EXPECT_LT(narrowed, builder.sample_count() / 4);
  for (int i = 0; i < mesh.vertex_count; ++i) {
    const auto k = static_cast<std::size_t>(3 * i);
    EXPECT_NEAR(Eigen::Vector3d(mesh.normals[k], mesh.normals[k + 1], mesh.normals[k + 2]).norm(), 1.0, 1e-5);
  }
}

TEST(TubeGeometryTest, FramesCarryOverBetweenBuilds) {
  TubeBuilder builder(TubeParams{}, 100);
  TubeMesh a = builder.make_mesh(2), b = builder.make_mesh(2);
  const IntestineModel model(IntestineParams{});
  ASSERT_TRUE(builder.build(model.rest().data(), model.columns(), 2, a));
  const Eigen::Vector3d n0 = builder.sample(0).normal;
  ASSERT_TRUE(builder.build(model.rest().data(), model.columns(), 2, b));
  EXPECT_LT((builder.sample(0).normal - n0).norm(), 1e-12);
  EXPECT_EQ(a.positions, b.positions);
}

TEST(TubeGeometryTest, BuildAndStripAllocateNothingAndRefuseBadInput) {
  TubeBuilder builder(TubeParams{}, 100);
  TubeMesh mesh = builder.make_mesh(kTubeMaxLod);
  const IntestineModel model(IntestineParams{});
  MesenteryMesh strip = make_mesentery_mesh(model.rows(), model.columns());
  {
    surgsim::test::AllocationCounter counter;
    for (int lod = 0; lod <= kTubeMaxLod; ++lod) {
      ASSERT_TRUE(builder.build(model.rest().data(), 100, lod, mesh));
      ASSERT_TRUE(builder.build(model.rest().data(), 100, lod, mesh, TubeSkinning::kGpu));  // matrices only
    }
    ASSERT_TRUE(mesentery_strip(model.rest().data(), strip));
    EXPECT_EQ(counter.count(), 0);
  }
  std::vector<double> bad(model.rest().data(), model.rest().data() + 300);
  bad[40] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(builder.build(bad.data(), 100, 2, mesh));
  EXPECT_EQ(mesh.index_count, 0);
  EXPECT_FALSE(builder.build(model.rest().data(), 101, 2, mesh));  // more than max_points
  EXPECT_FALSE(builder.build(model.rest().data(), 1, 2, mesh));
  TubeMesh small = builder.make_mesh(0);
  EXPECT_FALSE(builder.build(model.rest().data(), 100, 5, small));  // mesh made for a lower LOD
  const std::vector<double> same(30, 0.5);
  EXPECT_FALSE(builder.build(same.data(), 10, 2, mesh));  // all points coincide
  EXPECT_THROW(TubeBuilder(TubeParams{}, 1), Error);
  TubeParams tp;
  tp.ring_clearance = -1.0;
  EXPECT_THROW(TubeBuilder(tp, 10), Error);
}

TEST(TubeGeometryTest, MesenteryStripCoversTheGrid) {
  const IntestineModel model(IntestineParams{});
  MesenteryMesh m = make_mesentery_mesh(4, 100);
  EXPECT_EQ(m.index_count, 3 * 2 * 100 + 2 * 2);
  EXPECT_EQ(m.vertex_count, 400);
  ASSERT_TRUE(mesentery_strip(model.rest().data(), m));
  for (int i = 0; i < 400; ++i) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_FLOAT_EQ(m.positions[static_cast<std::size_t>(3 * i + c)], static_cast<float>(model.rest()(c, i)));
    }
  }
  // Every grid cell is covered by two non-degenerate strip triangles.
  int cells = 0;
  for (int i = 0; i + 2 < m.index_count; ++i) {
    const auto a = m.strip[static_cast<std::size_t>(i)], b = m.strip[static_cast<std::size_t>(i + 1)],
               c = m.strip[static_cast<std::size_t>(i + 2)];
    if (a != b && b != c && a != c) ++cells;
  }
  EXPECT_EQ(cells, 2 * 3 * 99);
  EXPECT_THROW(make_mesentery_mesh(1, 10), Error);
}


Eigen::Vector3d surface_point(const MesenterySurface& s, int v) {
  const auto k = static_cast<std::size_t>(3 * v);
  return {s.positions[k], s.positions[k + 1], s.positions[k + 2]};
}
Eigen::Vector3d surface_normal(const MesenterySurface& s, int v) {
  const auto k = static_cast<std::size_t>(3 * v);
  return {s.normals[k], s.normals[k + 1], s.normals[k + 2]};
}

// The model's rest grid with a smooth sag across the membrane (the folds hang and wave as under gravity and a probe):
// a curved sheet that is not the one the model starts from.
std::vector<double> sagged_rest(const IntestineModel& model) {
  std::vector<double> x(model.rest().data(), model.rest().data() + model.rest().size());
  for (int r = 0; r < model.rows(); ++r) {
    for (int c = 0; c < model.columns(); ++c) {
      const double w = 1.0 - static_cast<double>(r) / (model.rows() - 1);  // 0 on the fixed vessel row
      double* p = x.data() + 3 * (r * model.columns() + c);
      p[2] -= 0.04 * w * w * (1.0 + 0.5 * std::sin(0.3 * c));
      p[1] += 0.02 * w * std::cos(0.2 * c);
    }
  }
  return x;
}

// The smooth mesentery passes through the grid, its normals are unit, on the grid's side (the strip's central-
// difference normals) and along the normal of the refined mesh's own geometry, and every triangle winds counter-
// clockwise seen from them. The membrane is a fan pleated onto its root: where the intestine turns at a fold's crest
// the vessel row (all on the vessel) reverses along it and the sheet folds over there, so the normal turns over a
// short way near the root; away from the root (the outer half, where it is wide) adjacent normals never flip.
TEST(TubeGeometryTest, MesenterySurfaceInterpolatesTheGridWithUnitConsistentNormals) {
  const IntestineModel model(IntestineParams{});
  const int rows = model.rows(), cols = model.columns();
  for (const auto& x : {std::vector<double>(model.rest().data(), model.rest().data() + model.rest().size()),
                        sagged_rest(model)}) {
    MesenterySurface s = make_mesentery_surface(rows, cols, 4, 3);
    ASSERT_EQ(s.vertex_rows, 3 * 4 + 1);
    ASSERT_EQ(s.vertex_cols, 99 * 3 + 1);
    ASSERT_EQ(s.indices.size(), static_cast<std::size_t>(6 * (s.vertex_rows - 1) * (s.vertex_cols - 1)));
    ASSERT_TRUE(mesentery_surface(x.data(), s));
    EXPECT_EQ(s.degenerate_normals, 0);
    MesenteryMesh strip = make_mesentery_mesh(rows, cols);
    ASSERT_TRUE(mesentery_strip(x.data(), strip));
    const int vc = s.vertex_cols;
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < cols; ++c) {
        const int v = r * s.row_steps * vc + c * s.col_steps, g = r * cols + c;
        const Eigen::Vector3d grid(x[3 * g], x[3 * g + 1], x[3 * g + 2]);
        ASSERT_LT((surface_point(s, v) - grid).norm(), 1e-6) << "grid node " << r << ", " << c;
        const Eigen::Vector3d gn(strip.normals[3 * g], strip.normals[3 * g + 1], strip.normals[3 * g + 2]);
        if (r + 1 < rows) ASSERT_GT(surface_normal(s, v).dot(gn), 0.5) << "the grid's side at node " << r << ", " << c;
      }
    }
    double worst_unit = 0, worst_geometry = 1, worst_outer = 1;
    int regular = 0;
    for (int i = 0; i < s.vertex_rows; ++i) {
      for (int j = 0; j < vc; ++j) {
        const int v = i * vc + j;
        const Eigen::Vector3d n = surface_normal(s, v);
        worst_unit = std::max(worst_unit, std::abs(n.norm() - 1.0));
        if (2 * i <= s.vertex_rows) {
          if (j + 1 < vc) worst_outer = std::min(worst_outer, n.dot(surface_normal(s, v + 1)));
          worst_outer = std::min(worst_outer, n.dot(surface_normal(s, v + vc)));
        }
        // The refined mesh's own central-difference normal (one-sided on the borders), where the mesh is regular
        // there (its two directions at least 17 degrees apart).
        const Eigen::Vector3d du = surface_point(s, i * vc + std::min(j + 1, vc - 1)) -
                                   surface_point(s, i * vc + std::max(j - 1, 0));
        const Eigen::Vector3d dv = surface_point(s, std::min(i + 1, s.vertex_rows - 1) * vc + j) -
                                   surface_point(s, std::max(i - 1, 0) * vc + j);
        const Eigen::Vector3d cn = du.cross(dv);
        if (cn.norm() < 0.3 * du.norm() * dv.norm()) continue;
        ++regular;
        worst_geometry = std::min(worst_geometry, n.dot(cn.normalized()));
      }
    }
    EXPECT_LT(worst_unit, 1e-6);
    EXPECT_GT(regular, s.vertex_count * 9 / 10);
    EXPECT_GT(worst_geometry, 0.9) << "normals on the side and along the normal of the refined mesh";
    EXPECT_GT(worst_outer, 0.0) << "no flip between adjacent normals in the outer half";
    // Every triangle winds counter-clockwise seen from its vertices' normals, but for those the pleat's fold line
    // crosses (their vertices' normals on opposite sides).
    int against = 0, folded = 0;
    for (std::size_t t = 0; t < s.indices.size(); t += 3) {
      const int a = static_cast<int>(s.indices[t]), b = static_cast<int>(s.indices[t + 1]),
                c = static_cast<int>(s.indices[t + 2]);
      const Eigen::Vector3d na = surface_normal(s, a), nb = surface_normal(s, b), nc = surface_normal(s, c);
      if (na.dot(nb) < 0 || nb.dot(nc) < 0 || na.dot(nc) < 0) {
        ++folded;
        continue;
      }
      const Eigen::Vector3d fn = (surface_point(s, b) - surface_point(s, a)).cross(surface_point(s, c) - surface_point(s, a));
      if (fn.dot(na + nb + nc) <= 0) ++against;
    }
    EXPECT_EQ(against, 0);
    EXPECT_LT(folded, static_cast<int>(s.indices.size() / 3) / 50) << "the pleats' fold lines only";
  }
}

// On a grid sampled from a cylinder (axis x, radius R) the patch's normals are the cylinder's (radial, one side),
// and its points stay within a small fraction of the spacing of the cylinder: the refinement is smooth, not faceted.
TEST(TubeGeometryTest, MesenterySurfaceNormalsOfACylinderAreRadial) {
  const int rows = 6, cols = 12;
  const double radius = 0.1, dth = 0.25, dx = 0.03;
  std::vector<double> x;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) x.insert(x.end(), {c * dx, radius * std::cos(r * dth), radius * std::sin(r * dth)});
  }
  MesenterySurface s = make_mesentery_surface(rows, cols, 5, 4);
  ASSERT_TRUE(mesentery_surface(x.data(), s));
  // Everywhere, and inside the first and last grid intervals across the rows (whose one-sided end tangents make
  // the border intervals flatter).
  double worst_dot = 1, worst_radius = 0, inner_dot = 1, inner_radius = 0, worst_neighbour = 1;
  for (int v = 0; v < s.vertex_count; ++v) {
    const Eigen::Vector3d p = surface_point(s, v);
    const Eigen::Vector3d radial = Eigen::Vector3d(0, p.y(), p.z()).normalized();
    // du along +x, dv along increasing angle: du x dv points inwards.
    const double d = surface_normal(s, v).dot(-radial);
    const double e = std::abs(Eigen::Vector2d(p.y(), p.z()).norm() - radius);
    worst_dot = std::min(worst_dot, d);
    worst_radius = std::max(worst_radius, e);
    const int i = v / s.vertex_cols;
    if (i >= s.row_steps && i <= s.vertex_rows - 1 - s.row_steps) {
      inner_dot = std::min(inner_dot, d);
      inner_radius = std::max(inner_radius, e);
    }
    if (v + s.vertex_cols < s.vertex_count) {
      worst_neighbour = std::min(worst_neighbour, surface_normal(s, v).dot(surface_normal(s, v + s.vertex_cols)));
    }
  }
  EXPECT_GT(worst_dot, 0.99);
  EXPECT_LT(worst_radius, 0.006 * radius);  // the linear chord's sagitta at 0.25 rad is 0.8 % of R
  EXPECT_GT(inner_dot, 0.9999);
  EXPECT_LT(inner_radius, 0.0005 * radius);
  EXPECT_GT(worst_neighbour, std::cos(2.0 * dth / s.row_steps)) << "the normal turns with the surface, step by step";
  const std::size_t mid = static_cast<std::size_t>(s.vertex_count / 2);
  EXPECT_FLOAT_EQ(s.coords[2 * mid + 1], static_cast<float>(mid / s.vertex_cols) / (s.vertex_rows - 1));
}

// Rows converging to one point at both ends (a mesentery tapered to zero width): the patch degenerates there and
// the normals are borrowed from the nearest valid vertex of the same row; all stay unit, finite and on one side.
TEST(TubeGeometryTest, MesenterySurfaceTaperedToAPointKeepsUnitNormals) {
  const IntestineModel model(IntestineParams{});
  const int rows = model.rows(), cols = model.columns();
  std::vector<double> x = sagged_rest(model);
  for (const int c : {0, cols - 1}) {
    for (int r = 0; r + 1 < rows; ++r) {
      for (int k = 0; k < 3; ++k) x[3 * (r * cols + c) + k] = x[3 * ((rows - 1) * cols + c) + k];
    }
  }
  MesenterySurface s = make_mesentery_surface(rows, cols, 4, 3);
  ASSERT_TRUE(mesentery_surface(x.data(), s));
  EXPECT_GE(s.degenerate_normals, 2 * s.vertex_rows);  // the two end vertex columns
  for (int v = 0; v < s.vertex_count; ++v) {
    ASSERT_NEAR(surface_normal(s, v).norm(), 1.0, 1e-6) << v;
  }
  for (int i = 0; i < s.vertex_rows; ++i) {
    const int v = i * s.vertex_cols;
    EXPECT_GT(surface_normal(s, v).dot(surface_normal(s, v + 1)), 0.99) << "row " << i;
  }
}

TEST(TubeGeometryTest, MesenterySurfaceAllocatesNothingAndRefusesBadInput) {
  const IntestineModel model(IntestineParams{});
  MesenterySurface s = make_mesentery_surface(model.rows(), model.columns(), 4, 3);
  const std::vector<double> x = sagged_rest(model);
  {
    surgsim::test::AllocationCounter counter;
    ASSERT_TRUE(mesentery_surface(model.rest().data(), s));
    ASSERT_TRUE(mesentery_surface(x.data(), s));
    EXPECT_EQ(counter.count(), 0);
  }
  const std::vector<float> before = s.positions;
  std::vector<double> bad = x;
  bad[3 * 150 + 1] = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(mesentery_surface(bad.data(), s));
  EXPECT_EQ(s.positions, before);
  MesenterySurface empty;
  EXPECT_FALSE(mesentery_surface(x.data(), empty));
  EXPECT_THROW(make_mesentery_surface(1, 10, 2, 2), Error);
  EXPECT_THROW(make_mesentery_surface(4, 10, 0, 2), Error);
  EXPECT_THROW(make_mesentery_surface(4, 10, 2, 17), Error);
}

}  // namespace
}  // namespace surgsim::intestine
