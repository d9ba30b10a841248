#include "compliance/superposition.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>

#include <random>
#include <sstream>

#include "support/alloc_counter.h"
#include "core/error.h"
#include "support/liver_test_util.h"
#include "fem/static_solver.h"

using namespace surgsim::core;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::intestine;

namespace surgsim {
namespace {

std::vector<int> all_nodes(int n) {
  std::vector<int> v(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) v[static_cast<std::size_t>(i)] = i;
  return v;
}

// An organ with tensors for the haptic and visual consumers plus an "all" block (every node) for comparisons.
class SuperpositionTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    organ_ = test::box_organ(8, 6, 4).release();
    contacts_ = new std::vector<int>(contactable_nodes(organ_->mesh, organ_->fixed));
    auto rows = standard_row_sets(organ_->mesh, *contacts_);
    rows.push_back({"all", all_nodes(static_cast<int>(organ_->mesh.nodes.rows()))});
    tensors_ = new Tensors(precompute_tensors(organ_->model, *contacts_, rows, PrecomputeOptions()));
    reference_ = new StaticSolver(organ_->model);
  }
  static void TearDownTestSuite() {
    delete reference_;
    delete tensors_;
    delete contacts_;
    delete organ_;
  }

  static std::vector<Contact> random_contacts(int m, std::mt19937& rng) {
    std::uniform_real_distribution<double> d(-0.004, 0.004);
    std::vector<Contact> c;
    for (int node : test::pick(*contacts_, m, rng)) c.push_back({node, Eigen::Vector3d(d(rng), d(rng), d(rng))});
    return c;
  }
  static StaticSolution reference(const std::vector<Contact>& contacts) {
    std::vector<ImposedDisplacement> im;
    for (const auto& c : contacts) im.push_back({c.node, c.displacement, 7});
    return reference_->solve(im);
  }

  static test::Organ* organ_;
  static std::vector<int>* contacts_;
  static Tensors* tensors_;
  static StaticSolver* reference_;
};
test::Organ* SuperpositionTest::organ_ = nullptr;
std::vector<int>* SuperpositionTest::contacts_ = nullptr;
Tensors* SuperpositionTest::tensors_ = nullptr;
StaticSolver* SuperpositionTest::reference_ = nullptr;

TEST_F(SuperpositionTest, EqualsTheReferenceSolveForRandomMultiContactLoads) {
  std::mt19937 rng(1234);
  Superposition haptic(*tensors_, "haptic");
  Superposition all(*tensors_, "all");
  ContactSolution sol;
  Eigen::VectorXd u(3 * organ_->mesh.nodes.rows());
  for (int m : {1, 2, 5, 10, 20, 40}) {
    for (int trial = 0; trial < 3; ++trial) {
      const auto contacts = random_contacts(m, rng);
      ASSERT_EQ(haptic.solve(contacts.data(), m, sol), ContactStatus::kOk);
      ASSERT_EQ(sol.count, m);
      const StaticSolution ref = reference(contacts);
      // Forces: lambda per contact node equals the reaction of the reference solve.
      Eigen::MatrixX3d lambda(m, 3);
      Eigen::MatrixX3d ref_lambda(m, 3);
      for (int l = 0; l < m; ++l) {
        lambda.row(l) = sol.lambda[static_cast<std::size_t>(l)].transpose();
        const auto it = std::lower_bound(ref.imposed_nodes.begin(), ref.imposed_nodes.end(),
                                         sol.nodes[static_cast<std::size_t>(l)]);
        ref_lambda.row(l) = ref.reaction.row(it - ref.imposed_nodes.begin());
      }
      EXPECT_LT(test::rel_error(lambda, ref_lambda), 1e-9) << m;
      EXPECT_LT(test::rel_error(sol.tool_force, Eigen::Vector3d(-ref.total_reaction)), 1e-9) << m;
      // Displacements of every node.
      ASSERT_EQ(all.displacements(sol.nodes.data(), sol.lambda.data(), sol.count, u), ContactStatus::kOk);
      Eigen::VectorXd ref_u(u.size());
      for (Eigen::Index i = 0; i < ref.displacement.rows(); ++i)
        ref_u.segment<3>(3 * i) = ref.displacement.row(i).transpose();
      EXPECT_LT(test::rel_error(u, ref_u), 1e-9) << m;
      // The imposed displacements hold at the contact nodes.
      for (const auto& c : contacts) {
        Eigen::Vector3d uc;
        ASSERT_TRUE(haptic.displacement(c.node, sol, uc));
        EXPECT_LT((uc - c.displacement).norm(), 1e-9 * c.displacement.norm());
      }
    }
  }
}

// Another organ resting on this one (the bowel on the liver): known forces at surface nodes besides the instrument's
// imposed displacements. The reference is the test's own: K_ff from the assembled model, the imposed dofs eliminated,
// K_OO u_O = f_O - K_OI u* solved with Eigen's sparse LDL^T (not CHOLMOD, not the tensors); the contact forces are the
// reactions K_IO u_O + K_II u* - f_I.
TEST_F(SuperpositionTest, KnownLoadsBesideTheContactsEqualTheDirectSolve) {
  std::mt19937 rng(4321);
  Superposition haptic(*tensors_, "haptic");
  Superposition all(*tensors_, "all");
  const FixedSet& fixed = organ_->model.fixed;
  const Eigen::SparseMatrix<double>& kff = organ_->model.k_ff;
  const int nodes = static_cast<int>(organ_->mesh.nodes.rows());
  std::uniform_real_distribution<double> f(-0.05, 0.05);
  for (int m : {0, 1, 3, 8}) {
    for (int nb : {1, 6, 20}) {
      const auto contacts = random_contacts(m, rng);
      std::vector<Load> loads;
      for (int node : test::pick(*contacts_, nb + m, rng)) {
        bool taken = false;
        for (const auto& c : contacts) taken = taken || c.node == node;
        if (!taken && static_cast<int>(loads.size()) < nb)
          loads.push_back({node, Eigen::Vector3d(f(rng), f(rng), f(rng))});
      }
      ContactSolution sol;
      ASSERT_EQ(haptic.solve(contacts.data(), m, loads.data(), static_cast<int>(loads.size()), sol),
                ContactStatus::kOk);
      // The reference: free dofs split into imposed (I) and others (O).
      const std::vector<int>& free_index = fixed.free_index();
      std::vector<int> role(static_cast<std::size_t>(kff.rows()), -1);  // index in I or O
      std::vector<bool> imposed(static_cast<std::size_t>(kff.rows()), false);
      Eigen::VectorXd ustar = Eigen::VectorXd::Zero(kff.rows()), load = Eigen::VectorXd::Zero(kff.rows());
      for (const auto& c : contacts)
        for (int d = 0; d < 3; ++d) {
          const int i = free_index[static_cast<std::size_t>(3 * c.node + d)];
          imposed[static_cast<std::size_t>(i)] = true;
          ustar[i] = c.displacement[d];
        }
      for (const auto& l : loads)
        for (int d = 0; d < 3; ++d) load[free_index[static_cast<std::size_t>(3 * l.node + d)]] += l.force[d];
      int no = 0;
      for (Eigen::Index i = 0; i < kff.rows(); ++i)
        if (!imposed[static_cast<std::size_t>(i)]) role[static_cast<std::size_t>(i)] = no++;
      std::vector<Eigen::Triplet<double>> t;
      Eigen::VectorXd rhs = Eigen::VectorXd::Zero(no);
      for (int col = 0; col < kff.outerSize(); ++col)
        for (Eigen::SparseMatrix<double>::InnerIterator it(kff, col); it; ++it) {
          const auto r = static_cast<std::size_t>(it.row());
          if (imposed[r]) continue;
          if (imposed[static_cast<std::size_t>(col)]) {
            rhs[role[r]] -= it.value() * ustar[col];
          } else {
            t.emplace_back(role[r], role[static_cast<std::size_t>(col)], it.value());
          }
        }
      for (Eigen::Index i = 0; i < kff.rows(); ++i)
        if (!imposed[static_cast<std::size_t>(i)]) rhs[role[static_cast<std::size_t>(i)]] += load[i];
      Eigen::SparseMatrix<double> koo(no, no);
      koo.setFromTriplets(t.begin(), t.end());
      Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(koo);
      ASSERT_EQ(ldlt.info(), Eigen::Success);
      const Eigen::VectorXd uo = ldlt.solve(rhs);
      Eigen::VectorXd ufree(kff.rows());
      for (Eigen::Index i = 0; i < kff.rows(); ++i)
        ufree[i] = imposed[static_cast<std::size_t>(i)] ? ustar[i] : uo[role[static_cast<std::size_t>(i)]];
      const Eigen::VectorXd reaction = kff * ufree - load;  // on the imposed dofs: the contact forces
      Eigen::VectorXd ref_u = Eigen::VectorXd::Zero(3 * nodes);
      for (int dof = 0; dof < 3 * nodes; ++dof) {
        const int i = free_index[static_cast<std::size_t>(dof)];
        if (i >= 0) ref_u[dof] = ufree[i];
      }
      // Forces: each contact's lambda is the reaction at its node.
      for (int l = 0; l < sol.count; ++l) {
        const int node = sol.nodes[static_cast<std::size_t>(l)];
        Eigen::Vector3d r;
        for (int d = 0; d < 3; ++d) r[d] = reaction[free_index[static_cast<std::size_t>(3 * node + d)]];
        EXPECT_LT(test::rel_error(sol.lambda[static_cast<std::size_t>(l)], r), 1e-9) << m << " " << nb;
      }
      // Displacements of every node: G lambda + G f_B.
      std::vector<int> at;
      std::vector<Eigen::Vector3d> force;
      for (int l = 0; l < sol.count; ++l) {
        at.push_back(sol.nodes[static_cast<std::size_t>(l)]);
        force.push_back(sol.lambda[static_cast<std::size_t>(l)]);
      }
      for (const auto& l : loads) {
        at.push_back(l.node);
        force.push_back(l.force);
      }
      Eigen::VectorXd u(3 * nodes);
      ASSERT_EQ(all.displacements(at.data(), force.data(), static_cast<int>(at.size()), u), ContactStatus::kOk);
      const double err = test::rel_error(u, ref_u);
      EXPECT_LT(err, 1e-9) << m << " contacts, " << nb << " loads";
      RecordProperty("rel_error_" + std::to_string(m) + "_" + std::to_string(nb), (std::ostringstream() << err).str());
    }
  }
}

TEST_F(SuperpositionTest, AKnownLoadOnANodeWithoutAColumnIsRefused) {
  Superposition haptic(*tensors_, "haptic");
  int interior = -1;
  for (int n = 0; n < tensors_->node_count && interior < 0; ++n)
    if (tensors_->column_of_node[static_cast<std::size_t>(n)] < 0 &&
        tensors_->fixed_mask[static_cast<std::size_t>(n)] == 0)
      interior = n;
  ASSERT_GE(interior, 0);
  const Contact c{(*contacts_)[0], Eigen::Vector3d(0, 0, -0.001)};
  const Load bad{interior, Eigen::Vector3d(0, 0, -0.1)};
  ContactSolution sol;
  EXPECT_EQ(haptic.solve(&c, 1, &bad, 1, sol), ContactStatus::kNotContactable);
  EXPECT_EQ(sol.bad_input, 1);
  EXPECT_EQ(sol.count, 0);
  const Load nan{(*contacts_)[1], Eigen::Vector3d(0, 0, std::nan(""))};
  EXPECT_EQ(haptic.solve(&c, 1, &nan, 1, sol), ContactStatus::kNonFinite);
  // ... also with no contact at all (nothing to solve, but the loads are still refused).
  EXPECT_EQ(haptic.solve(nullptr, 0, &bad, 1, sol), ContactStatus::kNotContactable);
  EXPECT_EQ(sol.bad_input, 0);
  EXPECT_EQ(haptic.solve(nullptr, 0, &nan, 1, sol), ContactStatus::kNonFinite);
}

TEST_F(SuperpositionTest, PaperFormAgrees) {
  std::mt19937 rng(99);
  Superposition all(*tensors_, "all");
  PaperTensors paper(*tensors_, "all");
  ContactSolution sol;
  Eigen::VectorXd u(3 * organ_->mesh.nodes.rows());
  for (int m : {1, 3, 8, 16}) {
    const auto contacts = random_contacts(m, rng);
    ASSERT_EQ(all.solve(contacts.data(), m, sol), ContactStatus::kOk);
    const PaperTensors::Solution p = paper.solve(contacts);
    ASSERT_EQ(p.status, ContactStatus::kOk);
    ASSERT_EQ(p.nodes.size(), static_cast<std::size_t>(m));
    for (int l = 0; l < m; ++l) {
      EXPECT_EQ(p.nodes[static_cast<std::size_t>(l)], sol.nodes[static_cast<std::size_t>(l)]);
      EXPECT_LT((p.lambda[static_cast<std::size_t>(l)] - sol.lambda[static_cast<std::size_t>(l)]).norm(),
                1e-9 * sol.tool_force.norm() + 1e-15);
      EXPECT_LT((p.corrected[static_cast<std::size_t>(l)] - sol.corrected[static_cast<std::size_t>(l)]).norm(),
                1e-9 * p.corrected[static_cast<std::size_t>(l)].norm());
      // u~_l = G_kk lambda_l, and lambda_from_corrected inverts it.
      Eigen::Vector3d back;
      ASSERT_EQ(all.lambda_from_corrected(&p.nodes[static_cast<std::size_t>(l)],
                                          &p.corrected[static_cast<std::size_t>(l)], 1, &back),
                ContactStatus::kOk);
      EXPECT_LT((back - sol.lambda[static_cast<std::size_t>(l)]).norm(), 1e-9 * sol.tool_force.norm() + 1e-15);
    }
    EXPECT_LT(test::rel_error(p.tool_force, sol.tool_force), 1e-9);
    all.displacements(sol.nodes.data(), sol.lambda.data(), sol.count, u);
    EXPECT_LT(test::rel_error(paper.displacements(p.nodes, p.corrected), u), 1e-9) << m;
  }
  // T^f_k is the force for a unit displacement at k alone; T^u_kk is the identity.
  const int c = tensors_->column_count() / 2;
  const int k = tensors_->contact_nodes[static_cast<std::size_t>(c)];
  const int r = tensors_->find("all")->row_of_node[static_cast<std::size_t>(k)];
  EXPECT_LT((paper.tu().block<3, 3>(3 * r, 3 * c) - Eigen::Matrix3d::Identity()).norm(), 1e-10);
  const Contact one{k, Eigen::Vector3d(0, 0, -0.001)};
  ASSERT_EQ(all.solve(&one, 1, sol), ContactStatus::kOk);
  EXPECT_LT((paper.tf(c) * one.displacement - sol.lambda[0]).norm(), 1e-9 * sol.lambda[0].norm());
}

TEST_F(SuperpositionTest, VisualBlockAgreesWithPerNodeEvaluation) {
  std::mt19937 rng(7);
  Superposition haptic(*tensors_, "haptic");
  const Superposition visual(*tensors_, "visual");
  ContactSolution sol;
  const auto contacts = random_contacts(6, rng);
  ASSERT_EQ(haptic.solve(contacts.data(), 6, sol), ContactStatus::kOk);
  Eigen::VectorXd u(3 * visual.block().row_count());
  ASSERT_EQ(visual.displacements(sol.nodes.data(), sol.lambda.data(), sol.count, u), ContactStatus::kOk);
  for (int r = 0; r < visual.block().row_count(); r += 11) {
    Eigen::Vector3d ur;
    ASSERT_EQ(visual.displacement(visual.block().row_nodes[static_cast<std::size_t>(r)], sol.nodes.data(),
                                  sol.lambda.data(), sol.count, ur),
              ContactStatus::kOk);
    EXPECT_LT((ur - u.segment<3>(3 * r)).norm(), 1e-15 + 1e-12 * u.norm());
  }
  // A clamped node does not move; an interior node is not a row of the haptic block.
  Eigen::Vector3d uf(1, 1, 1);
  EXPECT_TRUE(haptic.displacement(organ_->fixed.fixed_nodes().front(), sol, uf));
  EXPECT_EQ(uf, Eigen::Vector3d::Zero());
  for (int i = 0; i < tensors_->node_count; ++i)
    if (tensors_->column_of_node[static_cast<std::size_t>(i)] < 0 &&
        tensors_->fixed_mask[static_cast<std::size_t>(i)] == 0) {
      EXPECT_FALSE(haptic.displacement(i, sol, uf));
      break;
    }
  Eigen::VectorXd wrong(5);
  EXPECT_EQ(visual.displacements(sol.nodes.data(), sol.lambda.data(), sol.count, wrong), ContactStatus::kInvalidNode);
}

TEST_F(SuperpositionTest, DuplicatesAreMerged) {
  Superposition s(*tensors_, "haptic", 4);
  const int a = (*contacts_)[3], b = (*contacts_)[40];
  const std::vector<Contact> dup = {{a, Eigen::Vector3d(0, 0, -0.002)},
                                    {b, Eigen::Vector3d(0.001, 0, 0)},
                                    {a, Eigen::Vector3d(0, 0, -0.004)}};
  ContactSolution sol;
  ASSERT_EQ(s.solve(dup.data(), 3, sol), ContactStatus::kOk);
  EXPECT_EQ(sol.count, 2);
  EXPECT_EQ(sol.merged_duplicates, 1);
  EXPECT_NEAR(sol.duplicate_spread, 0.001, 1e-15);
  EXPECT_EQ(sol.nodes[0], a);
  EXPECT_LT((sol.displacement[0] - Eigen::Vector3d(0, 0, -0.003)).norm(), 1e-18);
  const std::vector<Contact> merged = {{a, Eigen::Vector3d(0, 0, -0.003)}, {b, Eigen::Vector3d(0.001, 0, 0)}};
  ContactSolution ref;
  ASSERT_EQ(s.solve(merged.data(), 2, ref), ContactStatus::kOk);
  EXPECT_EQ(sol.lambda[0], ref.lambda[0]);
  EXPECT_EQ(sol.tool_force, ref.tool_force);
  // Five entries over four distinct nodes fit a capacity of 4 once merged.
  std::vector<Contact> five = {{(*contacts_)[1], {0, 0, -1e-3}},
                               {(*contacts_)[2], {0, 0, -1e-3}},
                               {(*contacts_)[1], {0, 0, -1e-3}},
                               {(*contacts_)[4], {0, 0, -1e-3}},
                               {(*contacts_)[5], {0, 0, -1e-3}}};
  EXPECT_EQ(s.solve(five.data(), 5, sol), ContactStatus::kOk);
  five.push_back({(*contacts_)[6], {0, 0, -1e-3}});
  EXPECT_EQ(s.solve(five.data(), 6, sol), ContactStatus::kOverCapacity);
  EXPECT_EQ(sol.bad_input, 5);
}

TEST_F(SuperpositionTest, BadContactsAreRefusedWithAStatus) {
  Superposition s(*tensors_, "haptic", 8);
  ContactSolution sol;
  const int good = (*contacts_)[0];
  const int fixed_node = organ_->fixed.fixed_nodes().front();
  int interior = -1;
  for (int i = 0; i < tensors_->node_count && interior < 0; ++i)
    if (tensors_->column_of_node[static_cast<std::size_t>(i)] < 0 &&
        tensors_->fixed_mask[static_cast<std::size_t>(i)] == 0)
      interior = i;
  ASSERT_GE(interior, 0);
  auto status = [&](int node, const Eigen::Vector3d& d) {
    const Contact c[2] = {{good, Eigen::Vector3d(0, 0, -1e-3)}, {node, d}};
    const ContactStatus st = s.solve(c, 2, sol);
    EXPECT_EQ(sol.count, 0);
    EXPECT_EQ(sol.tool_force, Eigen::Vector3d::Zero());
    if (st != ContactStatus::kOk) {
      EXPECT_EQ(sol.bad_input, 1);
    }
    return st;
  };
  EXPECT_EQ(status(fixed_node, Eigen::Vector3d(0, 0, -1e-3)), ContactStatus::kFixedNode);
  EXPECT_EQ(status(interior, Eigen::Vector3d(0, 0, -1e-3)), ContactStatus::kNotContactable);
  EXPECT_EQ(status(-1, Eigen::Vector3d(0, 0, -1e-3)), ContactStatus::kInvalidNode);
  EXPECT_EQ(status(tensors_->node_count, Eigen::Vector3d(0, 0, -1e-3)), ContactStatus::kInvalidNode);
  EXPECT_EQ(status((*contacts_)[9], Eigen::Vector3d(NAN, 0, 0)), ContactStatus::kNonFinite);
  EXPECT_STREQ(to_string(ContactStatus::kFixedNode), "contact on a fixed node");
  EXPECT_THROW(Superposition bad(*tensors_, "nope"), Error);
  EXPECT_THROW(Superposition bad(*tensors_, "haptic", kMaxContacts + 1), Error);
  // No contact: no force.
  EXPECT_EQ(s.solve(nullptr, 0, sol), ContactStatus::kOk);
  EXPECT_EQ(sol.count, 0);
}

TEST_F(SuperpositionTest, NearSingularIsReportedNotThrown) {
  // Two neighbouring contact nodes: G_CC is well conditioned in exact terms; a strict threshold flags it. rcond is a
  // property of the contacts, so it is also reported on success.
  const int a = (*contacts_)[10], b = (*contacts_)[11];
  const Contact c[2] = {{a, Eigen::Vector3d(0, 0, -1e-3)}, {b, Eigen::Vector3d(0, 0, -1e-3)}};
  ContactSolution sol;
  Superposition normal(*tensors_, "haptic", 4);
  ASSERT_EQ(normal.solve(c, 2, sol), ContactStatus::kOk);
  EXPECT_GT(sol.rcond, 0);
  EXPECT_LT(sol.rcond, 1);
  Superposition strict(*tensors_, "haptic", 4, /*near_singular_rcond=*/1.0);
  EXPECT_EQ(strict.solve(c, 2, sol), ContactStatus::kNearSingular);
  EXPECT_EQ(sol.tool_force, Eigen::Vector3d::Zero());

  // A genuinely singular G_CC: a copy of the tensors in which two contact nodes share one column.
  Tensors twin = *tensors_;
  const int ca = twin.column_of_node[static_cast<std::size_t>(a)],
            cb = twin.column_of_node[static_cast<std::size_t>(b)];
  TensorBlock& h = twin.blocks[0];
  h.g.middleCols<3>(3 * cb) = h.g.middleCols<3>(3 * ca);
  h.g.middleRows<3>(3 * h.row_of_node[static_cast<std::size_t>(b)]) =
      h.g.middleRows<3>(3 * h.row_of_node[static_cast<std::size_t>(a)]);
  Superposition singular(twin, "haptic", 4);
  EXPECT_EQ(singular.solve(c, 2, sol), ContactStatus::kNearSingular);
}

TEST_F(SuperpositionTest, RunPhaseAllocatesNothing) {
  std::mt19937 rng(5);
  Superposition haptic(*tensors_, "haptic", 20);
  const Superposition visual(*tensors_, "visual");
  const auto contacts = random_contacts(20, rng);
  ContactSolution sol;
  Eigen::VectorXd u(3 * visual.block().row_count());
  Eigen::Vector3d near[3];
  long allocations = 0;
  {
    test::AllocationCounter counter;
    for (int rep = 0; rep < 3; ++rep) {
      haptic.solve(contacts.data(), 20, sol);
      for (int i = 0; i < 3; ++i) haptic.displacement(contacts[static_cast<std::size_t>(i)].node, sol, near[i]);
      visual.displacements(sol.nodes.data(), sol.lambda.data(), sol.count, u);
      visual.lambda_from_corrected(sol.nodes.data(), sol.displacement.data(), 3, near);
    }
    allocations = counter.count();
  }
  EXPECT_EQ(sol.status, ContactStatus::kOk);
  EXPECT_EQ(allocations, 0);
  // The counter itself works.
  {
    test::AllocationCounter counter;
    std::vector<int> v(100);
    EXPECT_GE(counter.count(), 1);
  }
}

TEST(SuperpositionFloat, FloatTensorsAgreeToStoragePrecision) {
  auto organ = test::box_organ(6, 4, 3);
  const auto contacts = contactable_nodes(organ->mesh, organ->fixed);
  PrecomputeOptions opts;
  opts.precision = Precision::kFloat;
  const Tensors t = precompute_tensors(organ->model, contacts, standard_row_sets(organ->mesh, contacts), opts);
  Superposition s(t, "visual");
  std::mt19937 rng(3);
  const auto picked = test::pick(contacts, 5, rng);
  std::vector<Contact> c;
  for (int k : picked) c.push_back({k, Eigen::Vector3d(0.001, -0.002, -0.003)});
  ContactSolution sol;
  ASSERT_EQ(s.solve(c.data(), 5, sol), ContactStatus::kOk);
  StaticSolver ref(organ->model);
  std::vector<ImposedDisplacement> im;
  for (const auto& x : c) im.push_back({x.node, x.displacement, 7});
  const StaticSolution r = ref.solve(im);
  EXPECT_LT(test::rel_error(sol.tool_force, Eigen::Vector3d(-r.total_reaction)), 1e-4);
}

// --- The near-singular guard: rcond is a real estimate of 1 / cond_1(G_CC). ---

// Tensors whose "haptic" block is the given symmetric 3N x 3N matrix, every node a contact node and a row.
Tensors synthetic_tensors(const Eigen::MatrixXd& g) {
  const int n = static_cast<int>(g.rows() / 3);
  Tensors t;
  t.node_count = n;
  t.contact_nodes = all_nodes(n);
  t.column_of_node = all_nodes(n);
  t.fixed_mask.assign(static_cast<std::size_t>(n), 0);
  TensorBlock b;
  b.name = "haptic";
  b.row_nodes = all_nodes(n);
  b.row_of_node = all_nodes(n);
  b.g = g;
  t.blocks.push_back(b);
  return t;
}

// The exact reciprocal condition number in the 1-norm, 1 / (||A||_1 ||A^-1||_1).
double exact_rcond1(const Eigen::MatrixXd& a) {
  const Eigen::MatrixXd inv = a.inverse();
  return 1.0 / (a.cwiseAbs().colwise().sum().maxCoeff() * inv.cwiseAbs().colwise().sum().maxCoeff());
}

// min / max of the Cholesky diagonal, squared: the old guard's number.
double cholesky_diagonal_ratio_sq(const Eigen::MatrixXd& a) {
  const Eigen::VectorXd d = a.llt().matrixL().toDenseMatrix().diagonal();
  const double r = d.minCoeff() / d.maxCoeff();
  return r * r;
}

TEST(SuperpositionNearSingular, IllConditionedGccWithAnEvenCholeskyDiagonalIsFlagged) {
  // G_CC = L L^T with L unit lower triangular and -1 below the diagonal: every Cholesky pivot is 1 (so the old
  // (min/max diagonal)^2 was exactly 1 and the guard never fired), while cond(L) grows like 2^n: for 6 contacts
  // (18 x 18) cond_1(G_CC) is above 1e12. Scaled to liver-like compliances (m/N); rcond does not depend on scale.
  const int n = 18;
  Eigen::MatrixXd l = Eigen::MatrixXd::Identity(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < i; ++j) l(i, j) = -1;
  const Eigen::MatrixXd g = 1e-4 * l * l.transpose();
  ASSERT_GT(cholesky_diagonal_ratio_sq(g), 0.99) << "the construction: an even Cholesky diagonal";
  const double exact = exact_rcond1(g);
  ASSERT_LT(exact, 1e-12) << "the construction: ill-conditioned beyond the default threshold";

  const Tensors t = synthetic_tensors(g);
  std::vector<Contact> c;
  for (int k = 0; k < n / 3; ++k) c.push_back({k, Eigen::Vector3d(0, 0, -1e-3)});
  ContactSolution sol;
  Superposition s(t, "haptic");  // the default threshold, 1e-12
  EXPECT_EQ(s.solve(c.data(), static_cast<int>(c.size()), sol), ContactStatus::kNearSingular) << "rcond " << sol.rcond;
  EXPECT_LT(sol.rcond, 1e-12);
  // The estimate of ||G_CC^-1||_1 is a lower bound (Hager / Higham), so rcond is never below the exact value and
  // in practice within a small factor of it.
  EXPECT_GE(sol.rcond, exact * (1 - 1e-6));
  EXPECT_LE(sol.rcond, 10 * exact);
  EXPECT_EQ(sol.count, 0);
  EXPECT_EQ(sol.tool_force, Eigen::Vector3d::Zero());

  // A milder version of the same construction (-0.3 below the diagonal, cond_1 about 1e3): flagged by a strict
  // threshold, solved under the default one.
  Eigen::MatrixXd lm = Eigen::MatrixXd::Identity(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < i; ++j) lm(i, j) = -0.3;
  const Eigen::MatrixXd gm = 1e-4 * lm * lm.transpose();
  const double exact_m = exact_rcond1(gm);
  ASSERT_GT(cholesky_diagonal_ratio_sq(gm), 0.99);
  ASSERT_GT(exact_m, 1e-6);
  ASSERT_LT(exact_m, 1e-2);
  const Tensors tm = synthetic_tensors(gm);
  Superposition normal(tm, "haptic");
  ASSERT_EQ(normal.solve(c.data(), static_cast<int>(c.size()), sol), ContactStatus::kOk);
  EXPECT_GE(sol.rcond, exact_m * (1 - 1e-6));
  EXPECT_LE(sol.rcond, 10 * exact_m);
  Superposition strict(tm, "haptic", kMaxContacts, /*near_singular_rcond=*/10 * exact_m);
  EXPECT_EQ(strict.solve(c.data(), static_cast<int>(c.size()), sol), ContactStatus::kNearSingular);
}

TEST(SuperpositionNearSingular, WellConditionedGccIsSolvedWithItsConditionReported) {
  // A diagonally dominant G_CC: cond_1 below 3; solved even under a strict threshold, rcond close to the exact one.
  const int n = 12;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> d(-1, 1);
  Eigen::MatrixXd g = Eigen::MatrixXd::Identity(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < i; ++j) g(i, j) = g(j, i) = 0.05 * d(rng);
  g *= 2e-4;
  const double exact = exact_rcond1(g);
  ASSERT_GT(exact, 0.3);
  const Tensors t = synthetic_tensors(g);
  std::vector<Contact> c;
  for (int k = 0; k < n / 3; ++k) c.push_back({k, Eigen::Vector3d(1e-3, 0, -2e-3)});
  ContactSolution sol;
  Superposition s(t, "haptic", kMaxContacts, /*near_singular_rcond=*/0.1);
  ASSERT_EQ(s.solve(c.data(), static_cast<int>(c.size()), sol), ContactStatus::kOk);
  EXPECT_GE(sol.rcond, exact * (1 - 1e-9));
  EXPECT_LE(sol.rcond, 3 * exact);
  EXPECT_LE(sol.rcond, 1 + 1e-12);
}

TEST_F(SuperpositionTest, RcondEstimatesTheExactConditionOfRealContacts) {
  // G_CC of random contacts on the box organ's real tensors: rcond against the exact 1-norm value of the same G_CC.
  std::mt19937 rng(11);
  const TensorBlock& h = *tensors_->find("haptic");
  Superposition haptic(*tensors_, "haptic");
  ContactSolution sol;
  for (int m : {1, 2, 3, 5, 10, 20}) {
    for (int trial = 0; trial < 3; ++trial) {
      const auto contacts = random_contacts(m, rng);
      ASSERT_EQ(haptic.solve(contacts.data(), m, sol), ContactStatus::kOk);
      Eigen::MatrixXd gcc(3 * m, 3 * m);
      for (int a = 0; a < m; ++a)
        for (int b = 0; b < m; ++b) {
          const int ra = h.row_of_node[static_cast<std::size_t>(sol.nodes[static_cast<std::size_t>(a)])];
          const int cb = tensors_->column_of_node[static_cast<std::size_t>(sol.nodes[static_cast<std::size_t>(b)])];
          for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) gcc(3 * a + i, 3 * b + j) = h.at(3 * ra + i, 3 * cb + j);
        }
      const Eigen::MatrixXd sym = 0.5 * (gcc + gcc.transpose());
      const double exact = exact_rcond1(sym);
      EXPECT_GE(sol.rcond, exact * (1 - 1e-6)) << m;
      EXPECT_LE(sol.rcond, 3 * exact) << m;
    }
  }
}

}  // namespace
}  // namespace surgsim
