#include "fem/hyperelastic.h"

#include <Eigen/LU>
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <sstream>

#include "mesh/box_mesh.h"
#include "core/error.h"
#include "support/liver_test_util.h"
#include "nonlinear/nonlinear_law.h"
#include "fem/static_solver.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::nonlinear;
using namespace surgsim::intestine;

namespace surgsim {
namespace {

using test::top_patch;

std::vector<ImposedDisplacement> push(const std::vector<int>& nodes, const Eigen::Vector3d& d) {
  std::vector<ImposedDisplacement> out;
  for (int n : nodes) out.push_back({n, d, 7});
  return out;
}

Eigen::Matrix3d random_deformation_gradient(std::mt19937& rng, double amplitude) {
  std::uniform_real_distribution<double> uni(-amplitude, amplitude);
  Eigen::Matrix3d f = Eigen::Matrix3d::Identity();
  for (int i = 0; i < 9; ++i) f(i % 3, i / 3) += uni(rng);
  return f;
}

TEST(Hyperelastic, StressIsTheEnergyGradientAndTangentItsDerivative) {
  const LameParameters lame = lame_parameters(test::liver_material());
  std::mt19937 rng(3);
  for (int trial = 0; trial < 5; ++trial) {
    const Eigen::Matrix3d f = random_deformation_gradient(rng, 0.3);
    ASSERT_GT(f.determinant(), 0);
    const Eigen::Matrix3d p = neo_hookean_stress(f, lame);
    const Eigen::Matrix<double, 9, 9> a = neo_hookean_tangent(f, lame);
    const double h = 1e-6;
    for (int c = 0; c < 9; ++c) {
      Eigen::Matrix3d fp = f, fm = f;
      fp(c % 3, c / 3) += h;
      fm(c % 3, c / 3) -= h;
      const double dw = (neo_hookean_energy_density(fp, lame) - neo_hookean_energy_density(fm, lame)) / (2 * h);
      EXPECT_NEAR(dw, p(c % 3, c / 3), 1e-6 * p.norm());
      const Eigen::Matrix3d dp = (neo_hookean_stress(fp, lame) - neo_hookean_stress(fm, lame)) / (2 * h);
      for (int r = 0; r < 9; ++r) EXPECT_NEAR(dp(r % 3, r / 3), a(r, c), 1e-6 * a.norm()) << r << "," << c;
    }
  }
  // At F = I: stress free, and the tangent is the linear elasticity tensor (lambda d_ij d_kl + mu (d_ik d_jl + d_il
  // d_jk)).
  EXPECT_LT(neo_hookean_stress(Eigen::Matrix3d::Identity(), lame).norm(), 1e-12);
  const Eigen::Matrix<double, 9, 9> a0 = neo_hookean_tangent(Eigen::Matrix3d::Identity(), lame);
  EXPECT_NEAR(a0(0, 0), lame.lambda + 2 * lame.mu, 1e-9);
  EXPECT_NEAR(a0(0, 4), lame.lambda, 1e-9);  // dP_xx / dF_yy
  EXPECT_NEAR(a0(3, 3), lame.mu, 1e-9);      // dP_xy / dF_xy
  EXPECT_NEAR(a0(3, 1), lame.mu, 1e-9);      // dP_xy / dF_yx
}

TEST(Hyperelastic, ConsistentTangentMatchesFiniteDifferencesOfTheInternalForce) {
  auto organ = test::box_organ(4, 3, 2);
  const HyperelasticSolver solver(organ->model);
  const int ndof = 3 * organ->model.node_count();
  std::mt19937 rng(11);
  std::normal_distribution<double> gauss(0, 0.002);  // m, on 4 cm cells: strains of ~10 %
  Eigen::VectorXd u(ndof);
  for (int d = 0; d < ndof; ++d) u[d] = gauss(rng);
  Eigen::SparseMatrix<double> k;
  ASSERT_TRUE(solver.tangent_stiffness(u, k));
  EXPECT_LT((Eigen::MatrixXd(k) - Eigen::MatrixXd(k).transpose()).norm(), 1e-10 * k.norm());
  Eigen::VectorXd f0, fp, fm;
  double e0 = 0, ep = 0, em = 0;
  ASSERT_TRUE(solver.internal_force(u, f0, &e0));
  const double h = 1e-7;
  double worst_k = 0, worst_f = 0;
  for (int d = 0; d < ndof; d += 5) {
    Eigen::VectorXd up = u, um = u;
    up[d] += h;
    um[d] -= h;
    ASSERT_TRUE(solver.internal_force(up, fp, &ep));
    ASSERT_TRUE(solver.internal_force(um, fm, &em));
    const Eigen::VectorXd column = (fp - fm) / (2 * h);
    worst_k = std::max(worst_k, (column - Eigen::VectorXd(k.col(d))).norm() / k.col(d).norm());
    worst_f = std::max(worst_f, std::abs((ep - em) / (2 * h) - f0[d]) / f0.cwiseAbs().maxCoeff());
  }
  EXPECT_LT(worst_k, 1e-6);
  EXPECT_LT(worst_f, 1e-6);
  // At u = 0 the tangent is the linear stiffness.
  ASSERT_TRUE(solver.tangent_stiffness(Eigen::VectorXd::Zero(ndof), k));
  EXPECT_LT((k - organ->model.k).norm(), 1e-10 * organ->model.k.norm());
}

TEST(Hyperelastic, TinyIndentationMatchesTheLinearSolve) {
  auto organ = test::box_organ(8, 6, 4);
  const auto imposed = push(top_patch(organ->mesh, 0.08, 0.06, 0.025), Eigen::Vector3d(2e-8, -1e-8, -1e-7));
  ASSERT_GE(imposed.size(), 3u);
  StaticSolver linear(organ->model);
  const StaticSolution lin = linear.solve(imposed);
  HyperelasticOptions opts;
  opts.load_steps = 1;
  const HyperelasticSolution nl = HyperelasticSolver(organ->model, opts).solve(imposed);
  ASSERT_TRUE(nl.converged()) << nl.message;
  EXPECT_EQ(nl.imposed_nodes, lin.imposed_nodes);
  EXPECT_LT((nl.displacement - lin.displacement).norm() / lin.displacement.norm(), 1e-4);
  EXPECT_LT((nl.reaction - lin.reaction).norm() / lin.reaction.norm(), 1e-4);
  EXPECT_LT((nl.total_reaction - lin.total_reaction).norm() / lin.total_reaction.norm(), 1e-4);
}

// Homogeneous uniaxial stretch of a box with symmetry planes: x = 0 holds x, y = 0 holds y, z = 0 holds z; the face
// x = L is moved to l L along x, the lateral faces are free. P1 tets represent the homogeneous state exactly, so the
// discrete solution is the analytic one (nonlinear_law.h's neo_hookean_compression, the same model).
void uniaxial_patch(double stretch) {
  const Eigen::Vector3d size(0.1, 0.05, 0.04);
  TetMesh mesh = make_box_mesh(4, 3, 2, size);
  const int n = static_cast<int>(mesh.nodes.rows());
  std::vector<std::uint8_t> masks(static_cast<std::size_t>(n), 0);
  std::vector<ImposedDisplacement> imposed;
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c)
      if (std::abs(mesh.nodes(i, c)) < 1e-12) masks[static_cast<std::size_t>(i)] |= static_cast<std::uint8_t>(1u << c);
  for (int i = 0; i < n; ++i)
    if (std::abs(mesh.nodes(i, 0) - size.x()) < 1e-12)
      imposed.push_back({i, Eigen::Vector3d((stretch - 1) * size.x(), 0, 0), 1});
  test::Organ organ(std::move(mesh), test::liver_material(), FixedSet(masks));
  const HyperelasticSolution s = HyperelasticSolver(organ.model).solve(imposed);
  ASSERT_TRUE(s.converged()) << s.message;

  CylinderReference cyl;
  cyl.height = size.x();
  cyl.young_modulus = organ.material.young_modulus;
  cyl.poisson_ratio = organ.material.poisson_ratio;
  double lateral = 0, p11 = 0;
  if (stretch < 1) {
    const NeoHookeanPoint exact = neo_hookean_compression(cyl, (1 - stretch) * size.x());
    lateral = exact.lateral_stretch;
    p11 = -exact.force / cyl.area();
  } else {
    // Zero lateral stress: mu (l_t^2 - 1) + lambda ln(l l_t^2) = 0, by bisection (the residual increases with l_t).
    const LameParameters lame = lame_parameters(organ.material);
    double lo = 0.3, hi = 1.0;
    for (int it = 0; it < 200; ++it) {
      const double mid = 0.5 * (lo + hi);
      (lame.mu * (mid * mid - 1) + lame.lambda * std::log(stretch * mid * mid) > 0 ? hi : lo) = mid;
    }
    lateral = 0.5 * (lo + hi);
    p11 = (lame.mu * (stretch * stretch - 1) + lame.lambda * std::log(stretch * lateral * lateral)) / stretch;
  }
  double worst = 0;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d x = organ.mesh.nodes.row(i).transpose();
    const Eigen::Vector3d exact((stretch - 1) * x.x(), (lateral - 1) * x.y(), (lateral - 1) * x.z());
    worst = std::max(worst, (s.displacement.row(i).transpose() - exact).norm());
  }
  EXPECT_LT(worst / (std::abs(stretch - 1) * size.x()), 1e-8) << "stretch " << stretch;
  const double area = size.y() * size.z();
  EXPECT_NEAR(s.total_reaction.x(), p11 * area, 1e-8 * std::abs(p11 * area)) << "stretch " << stretch;
  EXPECT_NEAR(s.total_reaction.y(), 0, 1e-8 * std::abs(p11 * area));
  EXPECT_NEAR(s.total_reaction.z(), 0, 1e-8 * std::abs(p11 * area));
  // Large strain: far from the linear force E (l - 1) A.
  EXPECT_GT(std::abs(p11 * area - organ.material.young_modulus * (stretch - 1) * area), 0.03 * std::abs(p11 * area));
}

TEST(Hyperelastic, UniaxialCompressionPatchMatchesTheAnalyticStress) { uniaxial_patch(0.7); }
TEST(Hyperelastic, UniaxialStretchPatchMatchesTheAnalyticStress) { uniaxial_patch(1.3); }

TEST(Hyperelastic, NewtonConvergesQuadratically) {
  auto organ = test::box_organ(8, 6, 4);
  const auto imposed = push(top_patch(organ->mesh, 0.08, 0.06, 0.03), Eigen::Vector3d(0, 0, -0.012));
  HyperelasticOptions opts;
  opts.load_steps = 1;
  opts.residual_tolerance = 1e-12;
  const HyperelasticSolution s = HyperelasticSolver(organ->model, opts).solve(imposed);
  ASSERT_TRUE(s.converged()) << s.message;
  ASSERT_EQ(s.steps.size(), 1u);
  const HyperelasticStep& step = s.steps[0];
  std::ostringstream seq;
  for (double r : step.residuals) seq << r / step.force_scale << " ";
  ASSERT_GE(step.residuals.size(), 3u) << seq.str();
  EXPECT_EQ(step.line_search_halvings, 0) << seq.str();
  // In the asymptotic range each residual is at most a constant times the square of the previous one: count the
  // digits gained, which doubles (e_{k+1} <= C e_k^2 with e = |r| / scale, C = 100).
  int quadratic = 0;
  for (std::size_t k = 0; k + 1 < step.residuals.size(); ++k) {
    const double ek = step.residuals[k] / step.force_scale, ek1 = step.residuals[k + 1] / step.force_scale;
    if (ek < 1e-2 && ek1 > 1e-14) {
      EXPECT_LT(ek1, 100 * ek * ek) << seq.str();
      ++quadratic;
    }
  }
  EXPECT_GE(quadratic, 1) << seq.str();
  EXPECT_LT(step.residuals.back(), 1e-12 * step.force_scale);
}

TEST(Hyperelastic, LargeIndentationConvergesWithLoadStepsAndStiffensAgainstLinear) {
  auto organ = test::box_organ(8, 6, 4);
  const auto imposed = push(top_patch(organ->mesh, 0.08, 0.06, 0.03), Eigen::Vector3d(0, 0, -0.024));  // 30 %
  const HyperelasticSolution s = HyperelasticSolver(organ->model).solve(imposed);
  ASSERT_TRUE(s.converged()) << s.message;
  EXPECT_EQ(s.load_factor, 1.0);
  EXPECT_GE(s.steps.size(), 10u);
  EXPECT_TRUE(s.displacement.allFinite());
  EXPECT_GT(s.min_jacobian, 0);
  for (const auto& step : s.steps) {
    if (!step.converged) continue;
    EXPECT_TRUE(step.reaction.allFinite());
    EXPECT_EQ(step.reaction.rows(), static_cast<Eigen::Index>(s.imposed_nodes.size()));
  }
  // Each converged step's force grows with the load.
  double last = 0;
  for (const auto& step : s.steps)
    if (step.converged) {
      EXPECT_GT(std::abs(step.total_reaction.z()), last);
      last = std::abs(step.total_reaction.z());
    }
  const StaticSolution lin = StaticSolver(organ->model).solve(imposed);
  EXPECT_GT(std::abs(s.total_reaction.z() - lin.total_reaction.z()), 0.01 * std::abs(lin.total_reaction.z()));
}

TEST(Hyperelastic, InversionIsAClearStatusWithAFiniteState) {
  auto organ = test::box_organ(4, 3, 2);
  // One top node pushed 0.3 m down through a 0.08 m thick box: some tet must invert.
  const auto imposed = push(top_patch(organ->mesh, 0.08, 0.04, 1e-6), Eigen::Vector3d(0, 0, -0.3));
  ASSERT_EQ(imposed.size(), 1u);
  HyperelasticOptions opts;
  opts.load_steps = 2;
  opts.max_step_cuts = 4;
  const HyperelasticSolution s = HyperelasticSolver(organ->model, opts).solve(imposed);
  EXPECT_EQ(s.status, HyperelasticStatus::kInverted) << s.message;
  EXPECT_FALSE(s.converged());
  EXPECT_LT(s.load_factor, 1.0);
  EXPECT_GE(s.inverted_tet, 0);
  EXPECT_NE(s.message.find("inverts"), std::string::npos) << s.message;
  EXPECT_TRUE(s.displacement.allFinite());
  EXPECT_TRUE(s.reaction.allFinite());
  EXPECT_GT(s.min_jacobian, 0);  // the returned state is the last converged one
}

TEST(Hyperelastic, BadInputAndOptionsThrow) {
  auto organ = test::box_organ(4, 3, 2);
  HyperelasticOptions bad;
  bad.load_steps = 0;
  EXPECT_THROW(HyperelasticSolver(organ->model, bad), Error);
  const HyperelasticSolver solver(organ->model);
  EXPECT_THROW(solver.solve({{-1, Eigen::Vector3d::Zero(), 7}}), Error);
  EXPECT_THROW(solver.solve({{0, Eigen::Vector3d::Zero(), 7}}), Error);  // node 0 sits on the clamped bottom
  const int top = top_patch(organ->mesh, 0.08, 0.04, 1e-6).at(0);
  EXPECT_THROW(solver.solve({{top, Eigen::Vector3d(0, 0, std::nan("")), 7}}), Error);
  // Nothing imposed: the rest state.
  const HyperelasticSolution rest = solver.solve({});
  EXPECT_TRUE(rest.converged());
  EXPECT_EQ(rest.displacement.norm(), 0);
}

TEST(Hyperelastic, SolveIsDeterministic) {
  auto organ = test::box_organ(6, 4, 3);
  const auto imposed = push(top_patch(organ->mesh, 0.08, 0.06, 0.03), Eigen::Vector3d(0.002, 0, -0.01));
  const HyperelasticSolver solver(organ->model);
  const HyperelasticSolution a = solver.solve(imposed), b = solver.solve(imposed);
  ASSERT_TRUE(a.converged());
  EXPECT_EQ((a.displacement - b.displacement).cwiseAbs().maxCoeff(), 0);
  EXPECT_EQ((a.reaction - b.reaction).cwiseAbs().maxCoeff(), 0);
  EXPECT_EQ(a.total_iterations, b.total_iterations);
}

}  // namespace
}  // namespace surgsim
