// The elasticity of a cut mesh is exact: a slab fixed on its underside is cut by a blade that goes in from the top
// and stops halfway down; the project's precomputation of the cut mesh, asked for the columns of the nodes on the
// crack's lips only (what a cutting organ computes first, for its current contacts), gives every boundary node's
// displacement under a unit force on a lip node equal to a direct solve of the cut mesh's own assembly
// (tests/support/direct_solve.h: stiffness assembled tet by tet there, Eigen's SparseLU; neither the FEM library nor
// CHOLMOD) to 1e-9 relative. And the cut is mechanical: pulling one lip moves its twin on the other lip less than
// half as far (the same two points were one node before the cut).
#include <gtest/gtest.h>

#include <cmath>
#include <algorithm>
#include <cstdio>
#include <vector>

#include "compliance/precompute.h"
#include "cut/cut.h"
#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "mesh/box_mesh.h"
#include "mesh/mesh.h"
#include "support/direct_solve.h"

namespace surgsim::cut {
namespace {

constexpr double kYoung = 3000.0, kPoisson = 0.45;

TEST(CutElasticity, TheLipsColumnsOfACutSlabMatchADirectSolveOfItsOwnAssembly) {
  // A 6 x 4 x 3 cm slab, 8 x 5 x 4 cells, fixed at z = 0; the blade x = 0.0315 (between node planes) from above the
  // top down to z = 0.015, across the whole width.
  mesh::TetMesh m = mesh::make_box_mesh(8, 5, 4, Eigen::Vector3d(0.06, 0.04, 0.03));
  const double xc = 0.0315;
  const Blade blade = blade_quad(Eigen::Vector3d(xc, -0.01, 0.015), Eigen::Vector3d(xc, 0.05, 0.015),
                                 Eigen::Vector3d(xc, 0.05, 0.04), Eigen::Vector3d(xc, -0.01, 0.04));
  const CutResult r = apply_cut(m, blade);
  ASSERT_EQ(r.status, CutStatus::kApplied) << r.reason;
  ASSERT_GT(r.nodes_duplicated, 0);

  std::vector<int> fixed_nodes;
  for (Eigen::Index n = 0; n < m.nodes.rows(); ++n) {
    if (m.nodes(n, 2) < 1e-12) fixed_nodes.push_back(static_cast<int>(n));
  }
  const fem::FixedSet fixed(static_cast<int>(m.nodes.rows()), fixed_nodes);
  fem::Material material;
  material.young_modulus = kYoung;
  material.poisson_ratio = kPoisson;
  const fem::ElasticModel model = fem::build_elastic_model(m, material, fixed);

  // The lips' twins: pairs of distinct nodes at one position on the top surface (z = 0.03).
  std::vector<std::pair<int, int>> twins;
  for (Eigen::Index a = 0; a < m.nodes.rows(); ++a) {
    if (std::abs(m.nodes(a, 2) - 0.03) > 1e-12) continue;
    for (Eigen::Index b = a + 1; b < m.nodes.rows(); ++b) {
      if ((m.nodes.row(a) - m.nodes.row(b)).norm() < 1e-12)
        twins.emplace_back(static_cast<int>(a), static_cast<int>(b));
    }
  }
  ASSERT_GE(twins.size(), 3u) << "the top edge of the crack has both lips";
  std::vector<int> lips;
  for (const auto& [a, b] : twins) {
    lips.push_back(a);
    lips.push_back(b);
  }
  std::sort(lips.begin(), lips.end());

  const std::vector<int> contactable = compliance::contactable_nodes(m, fixed);
  std::vector<compliance::RowSet> rows = {compliance::RowSet{"haptic", lips}};
  for (const compliance::RowSet& s : compliance::standard_row_sets(m, fixed, contactable)) {
    if (s.name == "visual") rows.push_back(s);
  }
  compliance::PrecomputeOptions options;
  options.memory_limit_mb = 0;
  const compliance::Tensors g = compliance::precompute_tensors(model, lips, rows, options);
  const compliance::TensorBlock* visual = g.find("visual");
  ASSERT_NE(visual, nullptr);

  const test::DirectReference reference(m.nodes, m.tets, kYoung, kPoisson, fixed_nodes);
  double worst = 0;
  for (int c = 0; c < g.column_count(); ++c) {
    const int node = g.contact_nodes[static_cast<std::size_t>(c)];
    for (int k = 0; k < 3; ++k) {
      const Eigen::MatrixX3d u = reference.displacements({{node, Eigen::Vector3d::Unit(k)}});
      const double scale = u.cwiseAbs().maxCoeff();
      for (int row = 0; row < visual->row_count(); ++row) {
        const int n = visual->row_nodes[static_cast<std::size_t>(row)];
        const Eigen::Vector3d col = visual->block3(row, c).col(k);
        worst = std::max(worst, (col - u.row(n).transpose()).cwiseAbs().maxCoeff() / scale);
      }
    }
  }
  std::printf(
      "cut slab: %d lip nodes (%zu twins), %d boundary rows; worst relative difference to the direct solve "
      "%.2e\n",
      g.column_count(), twins.size(), visual->row_count(), worst);
  EXPECT_LT(worst, 1e-9);

  // Pulling a lip apart from its twin (along -x on the -x lip): the twin moves less than half as far.
  for (const auto& [a, b] : twins) {
    const bool a_left = [&] {  // the lip a belongs to: the side of the plane its tets lie on
      for (Eigen::Index t = 0; t < m.tets.rows(); ++t) {
        for (int v = 0; v < 4; ++v) {
          if (m.tets(t, v) != a) continue;
          double cx = 0;
          for (int w = 0; w < 4; ++w) cx += 0.25 * m.nodes(m.tets(t, w), 0);
          return cx < xc;
        }
      }
      return true;
    }();
    const Eigen::Vector3d pull(a_left ? -1.0 : 1.0, 0.0, 0.0);
    const Eigen::MatrixX3d u = reference.displacements({{a, pull}});
    EXPECT_LT(std::abs(u(b, 0)), 0.5 * std::abs(u(a, 0))) << "twins " << a << ", " << b;
  }
}

}  // namespace
}  // namespace surgsim::cut
