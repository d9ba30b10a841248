// The patch solve against the full solve of the same constraint: K_ff u = C mu with C^T u = b,
// i.e. mu = (C^T K_ff^-1 C)^-1 b by a direct CHOLMOD solve of the assembled stiffness, no tensors. The patch solve
// reads the same compliance from the precomputed "haptic" block, so they agree to the storage precision; the error
// is printed (ctest -R common_liver_test -V).
#include "compliance/patch_solve.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <iostream>

#include "fem/cholmod_solver.h"
#include "contact/contact_surface.h"
#include "support/alloc_counter.h"
#include "support/liver_test_util.h"

using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::contact;

namespace surgsim {
namespace {

TEST(PatchSolve, EqualsTheFullSolveOfTheSameConstraint) {
  const auto organ = test::box_organ(8, 6, 4);
  const std::vector<int> contacts = contactable_nodes(organ->mesh, organ->fixed);
  const Tensors tensors = precompute_tensors(organ->model, contacts, standard_row_sets(organ->mesh, contacts), {});
  const SurfaceMesh surface = boundary_surface(organ->mesh);
  std::vector<std::uint8_t> free(static_cast<std::size_t>(organ->mesh.nodes.rows()), 0);
  for (int n : contacts) free[static_cast<std::size_t>(n)] = 1;
  const double radius = 2.5 * ContactSurface::mean_edge(organ->mesh, surface);
  const ContactSurface cs(organ->mesh, surface, free, radius);

  // Two tool points on the top face (z = 0.08): one frictionless (1 row along the patch normal), one sticking
  // (3 rows), their patches overlapping.
  PatchConstraints c;
  c.clear();
  const Eigen::Vector3d points[2] = {{0.0731, 0.0577, 0.08}, {0.0931, 0.0677, 0.08}};
  for (int p = 0; p < 2; ++p) {
    RestPoint rp;  // the closest rest point, by brute force over the triangles
    for (int f = 0; f < surface.tris.rows(); ++f) {
      const RestPoint r = cs.on_triangle(points[p] + Eigen::Vector3d(0, 0, -0.003), f);
      if (!rp.found || r.distance < rp.distance) rp = r;
    }
    ASSERT_NEAR(rp.point.z(), 0.08, 1e-12);
    std::array<int, kMaxContacts> nodes{};
    std::array<double, kMaxContacts> w{};
    const int n = cs.patch(rp.point, rp.triangle, rp.normal, kMaxContacts, nodes.data(), w.data(), nullptr, nullptr);
    ASSERT_GT(n, 6);
    const int start = c.patch_start[static_cast<std::size_t>(p)];
    for (int e = 0; e < n; ++e) {
      int u = 0;
      while (u < c.node_count && c.nodes[static_cast<std::size_t>(u)] != nodes[static_cast<std::size_t>(e)]) ++u;
      if (u == c.node_count) c.nodes[static_cast<std::size_t>(c.node_count++)] = nodes[static_cast<std::size_t>(e)];
      c.entry_node[static_cast<std::size_t>(start + e)] = u;
      c.entry_weight[static_cast<std::size_t>(start + e)] = w[static_cast<std::size_t>(e)];
    }
    c.patch_start[static_cast<std::size_t>(p + 1)] = start + n;
    c.patch_count = p + 1;
    const Eigen::Vector3d normal = cs.patch_normal(nodes.data(), w.data(), n);
    EXPECT_GT(normal.z(), 0.95);  // the patch reaches the box's edges, whose vertex normals lean out
    const Eigen::Vector3d dirs[3] = {normal, Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY()};
    for (int r = 0; r < (p == 0 ? 1 : 3); ++r) {
      c.row_patch[static_cast<std::size_t>(c.row_count)] = p;
      c.row_direction[static_cast<std::size_t>(c.row_count++)] = dirs[r];
    }
  }
  const double b[4] = {-0.003, -0.002, 0.0005, -0.0003};  // m

  PatchSolver solver(tensors, "haptic");
  ASSERT_EQ(solver.prepare(c), ContactStatus::kOk);
  ASSERT_EQ(solver.factor(c), ContactStatus::kOk);
  double mu[4];
  solver.solve(b, mu);
  std::array<Eigen::Vector3d, kMaxContacts> lambda;
  solver.node_forces(c, mu, lambda.data());

  // Full solve: C (free dofs x rows), X = K_ff^-1 C, A = C^T X, mu = A^-1 b, u = X mu.
  const auto& fi = organ->fixed.free_index();
  Eigen::MatrixXd cm = Eigen::MatrixXd::Zero(organ->fixed.free_dof_count(), c.row_count);
  for (int k = 0; k < c.row_count; ++k) {
    const int p = c.row_patch[static_cast<std::size_t>(k)];
    for (int e = c.patch_start[static_cast<std::size_t>(p)]; e < c.patch_start[static_cast<std::size_t>(p + 1)]; ++e) {
      const int node = c.nodes[static_cast<std::size_t>(c.entry_node[static_cast<std::size_t>(e)])];
      for (int a = 0; a < 3; ++a)
        cm(fi[static_cast<std::size_t>(3 * node + a)], k) +=
            c.entry_weight[static_cast<std::size_t>(e)] * c.row_direction[static_cast<std::size_t>(k)][a];
    }
  }
  CholmodSolver chol(organ->model.k_ff);
  const Eigen::MatrixXd x = chol.solve(cm);
  const Eigen::MatrixXd a_full = cm.transpose() * x;
  const Eigen::VectorXd mu_full = a_full.ldlt().solve(Eigen::Map<const Eigen::VectorXd>(b, 4));
  const Eigen::VectorXd u_full = x * mu_full;
  // Constraints hold in the full solve.
  EXPECT_LT((cm.transpose() * u_full - Eigen::Map<const Eigen::VectorXd>(b, 4)).norm(), 1e-12);

  const Eigen::VectorXd mu_patch = Eigen::Map<const Eigen::VectorXd>(mu, 4);
  const double mu_error = (mu_patch - mu_full).norm() / mu_full.norm();
  double u_error = 0, u_scale = 0;
  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  for (int u = 0; u < c.node_count; ++u) {
    const int node = c.nodes[static_cast<std::size_t>(u)];
    Eigen::Vector3d uf;
    for (int a = 0; a < 3; ++a) uf[a] = u_full(fi[static_cast<std::size_t>(3 * node + a)]);
    u_error = std::max(u_error, (solver.union_displacement(u, lambda.data(), c.node_count) - uf).norm());
    u_scale = std::max(u_scale, uf.norm());
    force -= lambda[static_cast<std::size_t>(u)];
  }
  std::cout << "[patch vs full solve] multipliers relative error " << mu_error << ", node displacements "
            << u_error / u_scale << " (tool force " << force.transpose() << " N)\n";
  RecordProperty("patch_vs_full_mu_rel_error", std::to_string(mu_error));
  EXPECT_LT(mu_error, 1e-9);
  EXPECT_LT(u_error / u_scale, 1e-9);

  // A second patch identical to the first is a dependent row: reported, not solved.
  PatchConstraints d = c;
  d.row_count = 2;
  d.row_patch[1] = 0;
  d.row_direction[1] = d.row_direction[0];
  ASSERT_EQ(solver.prepare(d), ContactStatus::kOk);
  EXPECT_EQ(solver.factor(d), ContactStatus::kNearSingular);
  EXPECT_EQ(solver.dependent_row(), 1);

  // The run phase allocates nothing.
  long allocations = 0;
  {
    test::AllocationCounter counter;
    for (int k = 0; k < 20; ++k) {
      solver.prepare(c);
      solver.factor(c);
      solver.solve(b, mu);
      solver.node_forces(c, mu, lambda.data());
    }
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0);
}

// A held contact keeps its union nodes from tick to tick and a second instrument appends its own: prepare()
// reads G only for the nodes that are new or moved, and the compliances are bit-identical to a fresh full read.
// Dense and packed symmetric (the shipped scenes') haptic blocks alike.
class PatchSolveReads : public ::testing::TestWithParam<bool> {};

TEST_P(PatchSolveReads, ReadsGOnlyForNewNodesAndGivesTheFullReadBitForBit) {
  const auto organ = test::box_organ(8, 6, 4);
  const std::vector<int> contacts = contactable_nodes(organ->mesh, organ->fixed);
  PrecomputeOptions options;
  if (GetParam()) options.symmetric_blocks = {"haptic"};
  const Tensors tensors = precompute_tensors(organ->model, contacts, standard_row_sets(organ->mesh, contacts), options);
  ASSERT_EQ(tensors.find("haptic")->symmetric, GetParam());
  ASSERT_GE(contacts.size(), 12u);
  // Patches over union nodes given as contactable-node indices, equal weights.
  const auto make = [&](const std::vector<std::vector<int>>& patches) {
    PatchConstraints c;
    c.clear();
    for (const auto& patch : patches) {
      const int p = c.patch_count;
      const int start = c.patch_start[static_cast<std::size_t>(p)];
      for (std::size_t e = 0; e < patch.size(); ++e) {
        const int node = contacts[static_cast<std::size_t>(patch[e])];
        int u = 0;
        while (u < c.node_count && c.nodes[static_cast<std::size_t>(u)] != node) ++u;
        if (u == c.node_count) c.nodes[static_cast<std::size_t>(c.node_count++)] = node;
        c.entry_node[static_cast<std::size_t>(start + static_cast<int>(e))] = u;
        c.entry_weight[static_cast<std::size_t>(start + static_cast<int>(e))] = 1.0 / static_cast<double>(patch.size());
      }
      c.patch_start[static_cast<std::size_t>(p + 1)] = start + static_cast<int>(patch.size());
      c.patch_count = p + 1;
    }
    return c;
  };
  const PatchConstraints one = make({{0, 1, 2, 3, 4, 5}});
  const PatchConstraints two = make({{0, 1, 2, 3, 4, 5}, {4, 5, 6, 7, 8, 9}});
  const PatchConstraints moved = make({{1, 0, 2, 3, 4, 5}, {4, 5, 6, 7, 8, 9}});
  const auto same = [](const PatchSolver& a, const PatchSolver& b, const PatchConstraints& c) {
    for (int i = 0; i < c.node_count; ++i)
      for (int j = 0; j < c.node_count; ++j)
        if (a.g(i, j) != b.g(i, j)) return false;
    for (int p = 0; p < c.patch_count; ++p)
      for (int q = 0; q < c.patch_count; ++q)
        if (a.compliance(p, q) != b.compliance(p, q)) return false;
    return true;
  };
  PatchSolver held(tensors, "haptic");
  ASSERT_EQ(held.prepare(one), ContactStatus::kOk);
  EXPECT_EQ(held.g_blocks_read(), 21u);  // 6 nodes: 6 x 7 / 2 blocks
  ASSERT_EQ(held.prepare(one), ContactStatus::kOk);
  EXPECT_EQ(held.g_blocks_read(), 21u) << "the same nodes: nothing read again";
  ASSERT_EQ(held.prepare(two), ContactStatus::kOk);
  EXPECT_EQ(held.g_blocks_read(), 21u + (55u - 21u)) << "only the blocks of the 4 appended nodes";
  PatchSolver fresh(tensors, "haptic");
  ASSERT_EQ(fresh.prepare(two), ContactStatus::kOk);
  EXPECT_TRUE(same(held, fresh, two));
  ASSERT_EQ(held.prepare(moved), ContactStatus::kOk);  // the first two nodes swapped: the same nodes, nothing read
  EXPECT_EQ(held.g_blocks_read(), 55u);
  PatchSolver fresh_moved(tensors, "haptic");
  ASSERT_EQ(fresh_moved.prepare(moved), ContactStatus::kOk);
  EXPECT_TRUE(same(held, fresh_moved, moved));
  ASSERT_EQ(held.prepare(one), ContactStatus::kOk);  // back to fewer nodes, in another order than the last read
  EXPECT_EQ(held.g_blocks_read(), 55u);
  PatchSolver fresh_one(tensors, "haptic");
  ASSERT_EQ(fresh_one.prepare(one), ContactStatus::kOk);
  EXPECT_TRUE(same(held, fresh_one, one));
  // A sliding footprint: node 0 leaves, node 10 enters in the middle of the order. Only node 10's blocks against the
  // six nodes of the union are read (its slot is node 0's, whose blocks are stale).
  const PatchConstraints slid = make({{1, 2, 10, 3, 4, 5}});
  ASSERT_EQ(held.prepare(slid), ContactStatus::kOk);
  EXPECT_EQ(held.g_blocks_read(), 55u + 6u);
  PatchSolver fresh_slid(tensors, "haptic");
  ASSERT_EQ(fresh_slid.prepare(slid), ContactStatus::kOk);
  EXPECT_TRUE(same(held, fresh_slid, slid));
  // The whole ring cycled through (more nodes than slots over time): still the values of a full read.
  for (int shift = 0; shift < 12; ++shift) {
    std::vector<int> patch;
    for (int e = 0; e < 6; ++e) patch.push_back((shift + e) % 12);
    const PatchConstraints ring = make({patch});
    ASSERT_EQ(held.prepare(ring), ContactStatus::kOk);
    PatchSolver fresh_ring(tensors, "haptic");
    ASSERT_EQ(fresh_ring.prepare(ring), ContactStatus::kOk);
    EXPECT_TRUE(same(held, fresh_ring, ring)) << "shift " << shift;
    // All union displacements in one product over the slots (stale slots in between) equal the per-node sums.
    std::vector<Eigen::Vector3d> lambda(static_cast<std::size_t>(ring.node_count)), batch(lambda.size());
    for (int u = 0; u < ring.node_count; ++u)
      lambda[static_cast<std::size_t>(u)] = Eigen::Vector3d(0.1 * u - 0.2, 0.05 * shift, 1.0 + u);
    held.union_displacements(lambda.data(), ring.node_count, batch.data());
    for (int u = 0; u < ring.node_count; ++u) {
      const Eigen::Vector3d one = fresh_ring.union_displacement(u, lambda.data(), ring.node_count);
      EXPECT_LE((batch[static_cast<std::size_t>(u)] - one).norm(), 1e-12 * one.norm()) << "shift " << shift;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Blocks, PatchSolveReads, ::testing::Values(false, true),
                         [](const ::testing::TestParamInfo<bool>& info) { return info.param ? "Packed" : "Dense"; });

}  // namespace
}  // namespace surgsim
