// apply_cut on box meshes: a plane through the whole box (two pieces of the analytic volumes), a blade stopping
// halfway (a crack whose lips have the blade's area), grazing and repeated cuts, a protected node, a thousand tiny
// random cuts, determinism, and the volume a 5 cm cut loses in a liver-sized box. The references (volumes, areas,
// boundary edge counts) are computed here, not by the code under test.
#include "cut/cut.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <random>
#include <vector>

#include "core/error.h"
#include "cut/components.h"
#include "mesh/box_mesh.h"
#include "mesh/mesh.h"

namespace surgsim::test {
namespace {

using cut::apply_cut;
using cut::CutResult;
using cut::CutStatus;
using Eigen::Vector3d;

double total_volume(const mesh::TetMesh& m) {
  double v = 0;
  for (int t = 0; t < m.tets.rows(); ++t) v += mesh::tet_volume(m, t);
  return v;
}

// The boundary faces (met once among all tets' faces), each with the tet it belongs to.
std::vector<std::array<int, 3>> boundary_faces(const mesh::TetMesh& m) {
  std::map<std::array<int, 3>, int> count;
  for (int t = 0; t < m.tets.rows(); ++t) {
    for (int f = 0; f < 4; ++f) {
      std::array<int, 3> k{};
      int j = 0;
      for (int c = 0; c < 4; ++c) {
        if (c != f) k[static_cast<std::size_t>(j++)] = m.tets(t, c);
      }
      std::sort(k.begin(), k.end());
      ++count[k];
    }
  }
  std::vector<std::array<int, 3>> out;
  for (const auto& [k, n] : count) {
    if (n == 1) out.push_back(k);
  }
  return out;
}

// Every boundary edge is used by exactly two boundary faces.
bool watertight(const mesh::TetMesh& m) {
  std::map<std::pair<int, int>, int> uses;
  for (const auto& k : boundary_faces(m)) {
    ++uses[{k[0], k[1]}];
    ++uses[{k[0], k[2]}];
    ++uses[{k[1], k[2]}];
  }
  for (const auto& [e, n] : uses) {
    if (n != 2) return false;
  }
  return !uses.empty();
}

double boundary_area(const mesh::TetMesh& m) {
  double a = 0;
  for (const auto& k : boundary_faces(m)) {
    const Vector3d p0 = m.nodes.row(k[0]).transpose(), p1 = m.nodes.row(k[1]).transpose();
    const Vector3d p2 = m.nodes.row(k[2]).transpose();
    a += 0.5 * (p1 - p0).cross(p2 - p0).norm();
  }
  return a;
}

bool valid(mesh::TetMesh m) {
  try {
    mesh::MeshValidation strict;
    strict.fix_orientation = false;
    mesh::validate_mesh(m, strict);
    return true;
  } catch (const core::Error& e) {
    ADD_FAILURE() << e.what();
    return false;
  }
}

// The plane x = c + a y + b z and a blade on it over y in [y0, y1], z in [z0, z1].
struct Plane {
  double c, a, b;
  double x(double y, double z) const { return c + a * y + b * z; }
  cut::Blade blade(double y0, double y1, double z0, double z1) const {
    return cut::blade_quad({x(y0, z0), y0, z0}, {x(y1, z0), y1, z0}, {x(y1, z1), y1, z1}, {x(y0, z1), y0, z1});
  }
};

// The box [0, 1] x [0, 0.8] x [0, 0.6] in 0.2 x 0.2 x (0.6 / nz) cells; the plane below keeps 0.04 m from its
// nodes, beyond the snap distance (0.1 of a mean edge of about 0.27 m).
mesh::TetMesh test_box(int nz = 3) { return mesh::make_box_mesh(5, 4, nz, {1.0, 0.8, 0.6}); }
const Plane kOblique{0.45, 0.1, 0.05};

TEST(CutPlane, FullCutLeavesTwoPiecesOfTheAnalyticVolumes) {
  mesh::TetMesh m = test_box();
  const mesh::TetMesh input = m;
  const CutResult r = apply_cut(m, kOblique.blade(-0.5, 1.3, -0.5, 1.1));
  ASSERT_EQ(r.status, CutStatus::kApplied) << r.reason;
  EXPECT_GT(r.elements_split, 0);
  EXPECT_GT(r.nodes_created, 0);
  EXPECT_GT(r.nodes_duplicated, 0);
  EXPECT_EQ(r.elements_removed, 0);
  EXPECT_TRUE(valid(m));
  EXPECT_TRUE(watertight(m));

  const double box = 1.0 * 0.8 * 0.6;
  // Volume on the side x < c + a y + b z: the integral of the plane's x over the box's y-z face.
  const double below = 0.8 * 0.6 * (kOblique.c + kOblique.a * 0.4 + kOblique.b * 0.3);
  EXPECT_NEAR(total_volume(m), box, 1e-9 * box);
  EXPECT_NEAR(r.volume_before, box, 1e-9 * box);
  EXPECT_NEAR(r.volume_after, box, 1e-9 * box);

  const cut::Components comp = cut::face_components(m);
  ASSERT_EQ(comp.count, 2);
  for (int c = 0; c < 2; ++c) {
    const mesh::TetMesh piece = cut::extract_component(m, comp, c).mesh;
    const Vector3d centroid = piece.nodes.colwise().mean().transpose();
    const bool is_below = centroid.x() < kOblique.x(centroid.y(), centroid.z());
    EXPECT_NEAR(total_volume(piece), is_below ? below : box - below, 1e-9 * box) << "piece " << c;
    EXPECT_TRUE(valid(piece));
    EXPECT_TRUE(watertight(piece));
  }

  // The face x = 0 is held: the piece below the plane is anchored, the other one is free.
  std::vector<int> fixed;
  for (int j = 0; j <= 4; ++j) {
    for (int k = 0; k <= 3; ++k) fixed.push_back(mesh::box_node(5, 4, 0, j, k));
  }
  const std::vector<bool> anchored = cut::anchored_components(m, comp, fixed);
  EXPECT_EQ(std::count(anchored.begin(), anchored.end(), true), 1);

  // A linear field carried onto the new nodes stays the same linear field (split points interpolate, copies copy).
  const auto linear = [](const Eigen::MatrixX3d& x) {
    Eigen::MatrixXd f(x.rows(), 2);
    f.col(0) = 2 * x.col(0) - x.col(1) + 0.5 * x.col(2);
    f.col(1) = x.col(2).array() + 1;
    return f;
  };
  const Eigen::MatrixXd carried = cut::carry_node_field(r, linear(input.nodes));
  ASSERT_EQ(carried.rows(), m.nodes.rows());
  EXPECT_LT((carried - linear(m.nodes)).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(CutPlane, SlightlyBentBladeStillSeparatesThePieces) {
  // A blade swept while turning: the quad's two triangles lie in planes 2 degrees apart.
  mesh::TetMesh m = test_box();
  const CutResult r =
      apply_cut(m, cut::blade_quad({0.47, -0.5, -0.5}, {0.52, 1.3, -0.5}, {0.42, 1.3, 1.1}, {0.47, -0.5, 1.1}));
  ASSERT_EQ(r.status, CutStatus::kApplied) << r.reason;
  EXPECT_TRUE(valid(m));
  EXPECT_TRUE(watertight(m));
  EXPECT_EQ(cut::face_components(m).count, 2);
  EXPECT_NEAR(total_volume(m), 0.48, 1e-9 * 0.48);
}

TEST(CutPlane, BladeStoppingHalfwayOpensACrackWithTheBladesArea) {
  // Layers of nodes at z = 0, 0.15, .., 0.6: the blade enters from the top and stops at the layer z = 0.3.
  mesh::TetMesh m = test_box(4);
  const double area_before = boundary_area(m);
  const std::size_t faces_before = boundary_faces(m).size();
  const CutResult r = apply_cut(m, kOblique.blade(-0.5, 1.3, 0.3, 0.9));
  ASSERT_EQ(r.status, CutStatus::kApplied) << r.reason;
  EXPECT_TRUE(valid(m));
  EXPECT_TRUE(watertight(m));
  EXPECT_EQ(cut::face_components(m).count, 1);
  EXPECT_GT(r.faces_opened, 0);
  EXPECT_GT(boundary_faces(m).size(), faces_before);
  EXPECT_NEAR(total_volume(m), 0.48, 1e-9 * 0.48);
  // Each lip has the blade's area inside the box (y in [0, 0.8], z in [0.3, 0.6]); the outer surface keeps its own.
  const double lip = 0.8 * 0.3 * std::sqrt(1 + kOblique.a * kOblique.a + kOblique.b * kOblique.b);
  EXPECT_NEAR(boundary_area(m) - area_before, 2 * lip, 1e-9 * lip);
}

TEST(CutPlane, GrazingPlaneThroughNodesSplitsNoElement) {
  // The plane x = 0.4 holds a layer of nodes; so does x = 0.4 + 1e-3 once snapped. The cut follows the existing
  // faces: no tet split, the pieces are the box's two sides of x = 0.4.
  for (const double offset : {0.0, 1e-3, -1e-3}) {
    mesh::TetMesh m = test_box();
    const Plane p{0.4 + offset, 0, 0};
    const CutResult r = apply_cut(m, p.blade(-0.5, 1.3, -0.5, 1.1));
    ASSERT_EQ(r.status, CutStatus::kApplied) << r.reason;
    EXPECT_EQ(r.elements_split, 0) << offset;
    EXPECT_EQ(r.nodes_created, 0) << offset;
    EXPECT_EQ(r.nodes_duplicated, 5 * 4) << offset;  // the layer's nodes
    EXPECT_TRUE(valid(m));
    EXPECT_TRUE(watertight(m));
    const cut::Components comp = cut::face_components(m);
    ASSERT_EQ(comp.count, 2);
    std::vector<double> volumes;
    for (int c = 0; c < 2; ++c) volumes.push_back(total_volume(cut::extract_component(m, comp, c).mesh));
    std::sort(volumes.begin(), volumes.end());
    EXPECT_NEAR(volumes[0], 0.4 * 0.48, 1e-12);
    EXPECT_NEAR(volumes[1], 0.6 * 0.48, 1e-12);
  }
}

TEST(CutPlane, SecondIdenticalCutChangesNothing) {
  for (const double z0 : {-0.5, 0.3}) {  // through, and stopping halfway
    mesh::TetMesh m = test_box(4);
    const cut::Blade blade = kOblique.blade(-0.5, 1.3, z0, 1.1);
    ASSERT_EQ(apply_cut(m, blade).status, CutStatus::kApplied);
    const std::uint64_t once = mesh::mesh_hash(m);
    const CutResult again = apply_cut(m, blade);
    ASSERT_EQ(again.status, CutStatus::kApplied) << again.reason;
    EXPECT_EQ(mesh::mesh_hash(m), once);
    EXPECT_EQ(again.elements_split, 0);
    EXPECT_EQ(again.nodes_created, 0);
    EXPECT_EQ(again.nodes_duplicated, 0);
    EXPECT_EQ(again.faces_opened, 0);
  }
}

TEST(CutPlane, CutThroughAProtectedNodeIsRefusedAndLeavesTheMesh) {
  mesh::TetMesh m = test_box();
  const std::uint64_t before = mesh::mesh_hash(m);
  const cut::Blade blade = Plane{0.4, 0, 0}.blade(-0.5, 1.3, -0.5, 1.1);
  cut::CutOptions options;
  options.protected_nodes = {mesh::box_node(5, 4, 0, 0, 0), mesh::box_node(5, 4, 2, 2, 1)};  // the second: x = 0.4
  const CutResult r = apply_cut(m, blade, options);
  EXPECT_EQ(r.status, CutStatus::kRefused);
  EXPECT_NE(r.reason.find("protected node " + std::to_string(mesh::box_node(5, 4, 2, 2, 1))), std::string::npos)
      << r.reason;
  EXPECT_EQ(mesh::mesh_hash(m), before);
  // Without the node on the plane the same cut goes through.
  options.protected_nodes = {mesh::box_node(5, 4, 0, 0, 0)};
  EXPECT_EQ(apply_cut(m, blade, options).status, CutStatus::kApplied);
  EXPECT_NE(mesh::mesh_hash(m), before);
}

TEST(CutPlane, BadBladesAreRefused) {
  mesh::TetMesh m = test_box();
  const std::uint64_t before = mesh::mesh_hash(m);
  cut::Blade flat;
  flat.triangles.push_back(Eigen::Matrix3d::Zero());
  EXPECT_EQ(apply_cut(m, flat).status, CutStatus::kRefused);
  cut::Blade nan = kOblique.blade(0, 1, 0, 1);
  nan.triangles[0](1, 1) = std::nan("");
  EXPECT_EQ(apply_cut(m, nan).status, CutStatus::kRefused);
  EXPECT_EQ(mesh::mesh_hash(m), before);
}

// Uniform in [0, 1) from a fixed 64-bit generator (the same numbers with any standard library).
double uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

TEST(CutPlane, AThousandTinyCutsEachLeaveAValidMesh) {
  // 50 runs of 20 cuts, each run from the uncut box: cuts on earlier cuts, with a mesh that stays small.
  const mesh::TetMesh box = mesh::make_box_mesh(3, 3, 3, {0.06, 0.06, 0.06});
  mesh::TetMesh m;
  std::mt19937_64 rng(20261208);
  const auto start = std::chrono::steady_clock::now();
  int applied = 0, opened = 0, refused = 0;
  for (int i = 0; i < 1000; ++i) {
    if (i % 20 == 0) {
      if (i > 0) {
        EXPECT_TRUE(watertight(m)) << "cut " << i;
      }
      m = box;
    }
    // A triangle of 2 to 8 mm about a point of the box, in a random plane.
    const Vector3d centre(0.06 * uniform(rng), 0.06 * uniform(rng), 0.06 * uniform(rng));
    cut::Blade blade;
    Eigen::Matrix3d tri;
    for (int k = 0; k < 3; ++k) {
      const Vector3d d(uniform(rng) - 0.5, uniform(rng) - 0.5, uniform(rng) - 0.5);
      tri.row(k) = (centre + (0.002 + 0.006 * uniform(rng)) * d.normalized()).transpose();
    }
    blade.triangles.push_back(tri);
    const std::uint64_t before = mesh::mesh_hash(m);
    const CutResult r = apply_cut(m, blade);
    if (r.status == CutStatus::kRefused) {
      EXPECT_EQ(mesh::mesh_hash(m), before) << "cut " << i << ": " << r.reason;
      if (refused++ < 3) std::printf("cut %d refused: %s\n", i, r.reason.c_str());
      continue;
    }
    ++applied;
    opened += r.faces_opened > 0 ? 1 : 0;
    ASSERT_TRUE(m.nodes.allFinite()) << "cut " << i;
    ASSERT_TRUE(valid(m)) << "cut " << i;
    EXPECT_NEAR(total_volume(m) + r.volume_removed, r.volume_before, 1e-9 * r.volume_before) << "cut " << i;
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("1000 tiny cuts: %d applied, %d opened faces, %d refused; last run %d nodes, %d tets; %.2f s\n", applied,
              opened, refused, static_cast<int>(m.nodes.rows()), static_cast<int>(m.tets.rows()), seconds);
  EXPECT_GT(applied, 900);
  EXPECT_GT(opened, 100);
  EXPECT_TRUE(watertight(m));
}

TEST(CutPlane, TheSameCutGivesTheSameMeshBitForBit) {
  const mesh::TetMesh input = test_box(4);
  const cut::Blade blade = kOblique.blade(-0.5, 1.3, 0.3, 0.9);
  mesh::TetMesh a = input, b = input;
  const CutResult ra = apply_cut(a, blade), rb = apply_cut(b, blade);
  ASSERT_EQ(ra.status, CutStatus::kApplied);
  EXPECT_EQ(ra.topology_hash, rb.topology_hash);
  EXPECT_EQ(ra.topology_hash, cut::cut_topology_hash(a));
  EXPECT_EQ(mesh::mesh_hash(a), mesh::mesh_hash(b));
  EXPECT_NE(ra.topology_hash, cut::cut_topology_hash(input));
}

TEST(CutPlane, FiveCentimetreCutAcrossALiverSizedBoxLosesAtMostHalfAPercent) {
  // A liver lobe's size, about 1400 nodes; a blade 5 cm into it from the side y = 0, through its whole thickness,
  // in an oblique plane.
  mesh::TetMesh m = mesh::make_box_mesh_with_nodes(1400, {0.15, 0.1, 0.08});
  const int nodes = static_cast<int>(m.nodes.rows()), tets = static_cast<int>(m.tets.rows());
  const double before = total_volume(m);
  const Vector3d n = Vector3d(1, 0.3, 0.1).normalized(), o(0.075, 0.0, 0.04);
  const Vector3d along = Vector3d::UnitZ().cross(n).normalized();  // in the plane, mostly +y
  const Vector3d up = n.cross(along);
  const double s = -0.01 / along.y(), e = 0.05 / along.y();  // y from -1 cm to 5 cm
  const cut::Blade blade = cut::blade_quad(o + s * along - 0.06 * up, o + e * along - 0.06 * up,
                                           o + e * along + 0.06 * up, o + s * along + 0.06 * up);
  const CutResult r = apply_cut(m, blade);
  ASSERT_EQ(r.status, CutStatus::kApplied) << r.reason;
  const double lost = (before - total_volume(m)) / before;
  std::printf(
      "liver-sized box (%d nodes, %d tets): 5 cm cut split %d tets into %d pieces, %d nodes created, %d duplicated, "
      "%d faces opened, %d removed, volume lost %.3g %%\n",
      nodes, tets, r.elements_split, r.elements_created, r.nodes_created, r.nodes_duplicated, r.faces_opened,
      r.elements_removed, 100 * lost);
  EXPECT_LE(lost, 0.005);
  EXPECT_GT(r.faces_opened, 0);
  EXPECT_TRUE(valid(m));
  EXPECT_TRUE(watertight(m));
  EXPECT_EQ(cut::face_components(m).count, 1);
}

}  // namespace
}  // namespace surgsim::test
