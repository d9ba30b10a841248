#include "fem/cholmod_solver.h"

#include <gtest/gtest.h>

#include <algorithm>

#include <Eigen/SparseCholesky>

#include "core/error.h"
#include "support/liver_test_util.h"

using namespace surgsim::core;
using namespace surgsim::fem;

namespace surgsim {
namespace {

TEST(CholmodSolver, MatchesEigenOnManyRightHandSidesInBlocks) {
  auto organ = test::box_organ(4, 3, 3);
  const auto& k = organ->model.k_ff;
  CholmodOptions opts;
  opts.block_columns = 7;  // force several blocks, the last one partial
  CholmodSolver solver(k, opts);
  EXPECT_TRUE(solver.factorized());
  EXPECT_EQ(solver.rows(), k.rows());
  EXPECT_GT(solver.factor_bytes(), 0u);
  const Eigen::MatrixXd b = Eigen::MatrixXd::Random(k.rows(), 20);
  const Eigen::MatrixXd x = solver.solve(b);
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ref(k);
  const Eigen::MatrixXd xr = ref.solve(b);
  EXPECT_LT(test::rel_error(x, xr), 1e-10);
  EXPECT_LT((k * x - b).norm() / b.norm(), 1e-12);
  // Solving again reuses the workspace and gives the same bits.
  const Eigen::MatrixXd x2 = solver.solve(b);
  EXPECT_EQ(0, std::memcmp(x.data(), x2.data(), sizeof(double) * static_cast<std::size_t>(x.size())));
}

TEST(CholmodSolver, RefactorizeKeepsTheAnalysisAndRefusesAnotherPattern) {
  // New values in the same pattern (a Newton loop's tangent, nonlinear/multirate.h): the new matrix's solution.
  auto organ = test::box_organ(3, 3, 2);
  Eigen::SparseMatrix<double> k = organ->model.k_ff;
  CholmodSolver solver(k);
  for (int j = 0; j < k.outerSize(); ++j)
    for (Eigen::SparseMatrix<double>::InnerIterator it(k, j); it; ++it)
      if (it.row() == j) it.valueRef() *= 3;  // still symmetric positive definite, other values
  solver.refactorize(k);
  const Eigen::VectorXd b = Eigen::VectorXd::Random(k.rows());
  Eigen::VectorXd x(b.size());
  solver.solve(b, x);
  EXPECT_LT((k * x - b).norm() / b.norm(), 1e-12);
  Eigen::SparseMatrix<double> other = k;
  other.coeffRef(0, k.rows() - 1) = 1e-3;  // a new entry in the upper triangle
  other.coeffRef(k.rows() - 1, 0) = 1e-3;
  EXPECT_THROW(solver.refactorize(other), Error);
  EXPECT_THROW(CholmodSolver().refactorize(k), Error);
}

TEST(CholmodSolver, SimplicialWorksToo) {
  auto organ = test::box_organ(3, 3, 2);
  CholmodOptions opts;
  opts.supernodal = false;
  CholmodSolver solver(organ->model.k_ff, opts);
  const Eigen::VectorXd b = Eigen::VectorXd::Random(organ->model.k_ff.rows());
  Eigen::VectorXd x(b.size());
  solver.solve(b, x);
  EXPECT_LT((organ->model.k_ff * x - b).norm() / b.norm(), 1e-12);
}

TEST(CholmodSolver, IndefiniteMatrixIsAClearError) {
  Eigen::SparseMatrix<double> a(3, 3);
  a.insert(0, 0) = 1;
  a.insert(1, 1) = -1;
  a.insert(2, 2) = 1;
  CholmodSolver solver;
  solver.analyze(a);
  try {
    solver.factorize();
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not positive definite"), std::string::npos) << e.what();
  }
}

TEST(CholmodSolver, MisuseIsAnError) {
  CholmodSolver solver;
  Eigen::MatrixXd b(2, 1);
  EXPECT_THROW(solver.solve(b), Error);
  Eigen::SparseMatrix<double> a(2, 3);
  EXPECT_THROW(solver.analyze(a), Error);
}

// rcond: CHOLMOD's (min / max diagonal of L)^2; diag(1, 4, 100) has L = diag(1, 2, 10).
TEST(CholmodSolver, ReciprocalConditionEstimate) {
  Eigen::SparseMatrix<double> a(3, 3);
  a.insert(0, 0) = 1;
  a.insert(1, 1) = 4;
  a.insert(2, 2) = 100;
  CholmodSolver solver;
  solver.analyze(a);
  EXPECT_EQ(solver.rcond(), 0.0) << "not factorized yet";
  solver.factorize();
  EXPECT_NEAR(solver.rcond(), 0.01, 1e-15);
}

// The selected unit-column solves on the shared supernodal factor.
TEST(CholmodSolver, UnitColumnsMatchTheFullSolveAtTheNeededRows) {
  auto organ = test::box_organ(5, 4, 3);
  const auto& k = organ->model.k_ff;
  const int n = static_cast<int>(k.rows());
  CholmodSolver solver(k);
  const std::vector<int> rhs = {0, 17, 5, n - 1, n / 2, 33};
  Eigen::MatrixXd e = Eigen::MatrixXd::Zero(n, static_cast<Eigen::Index>(rhs.size()));
  for (std::size_t j = 0; j < rhs.size(); ++j) e(rhs[j], static_cast<Eigen::Index>(j)) = 1;
  const Eigen::MatrixXd ref = solver.solve(e);
  CholmodSolver::UnitSolveWork all, some;
  solver.solve_unit_columns(rhs.data(), static_cast<int>(rhs.size()), solver.supernodes_for_rows({}), all);
  Eigen::MatrixXd x(n, static_cast<Eigen::Index>(rhs.size()));
  for (int f = 0; f < n; ++f)
    for (std::size_t j = 0; j < rhs.size(); ++j)
      x(f, static_cast<Eigen::Index>(j)) =
          all.x[static_cast<std::size_t>(solver.permuted_row(f)) + static_cast<std::size_t>(n) * j];
  EXPECT_LT(test::rel_error(x, ref), 1e-12);
  // Only some rows needed: the backward solve skips the other supernodes, the needed rows keep their bits.
  const std::vector<int> needed = {3, 40, n - 2};
  const std::vector<char> mask = solver.supernodes_for_rows(needed);
  EXPECT_LT(std::count(mask.begin(), mask.end(), 1), static_cast<long>(mask.size()));
  solver.solve_unit_columns(rhs.data(), static_cast<int>(rhs.size()), mask, some);
  for (int f : needed)
    for (std::size_t j = 0; j < rhs.size(); ++j) {
      const std::size_t at = static_cast<std::size_t>(solver.permuted_row(f)) + static_cast<std::size_t>(n) * j;
      EXPECT_EQ(some.x[at], all.x[at]) << "row " << f << " column " << j;
    }
  // A simplicial factor has no supernodes to share.
  CholmodOptions simplicial;
  simplicial.supernodal = false;
  CholmodSolver s2(k, simplicial);
  EXPECT_THROW(s2.solve_unit_columns(rhs.data(), 1, mask, some), Error);
}

}  // namespace
}  // namespace surgsim
