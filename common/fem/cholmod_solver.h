// RAII wrapper over CHOLMOD's supernodal sparse Cholesky: analyse and factor once, then solve any number of
// right-hand sides in column blocks (libigl's precompute/solve split). One cholmod_common per solver, reused.
#pragma once
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <cstddef>
#include <memory>
#include <vector>

namespace surgsim::fem {

struct CholmodOptions {
  bool supernodal = true;   // supernodal (BLAS-3) factor; false = simplicial
  int block_columns = 192;  // right-hand sides per cholmod_solve2 call in solve()
};

class CholmodSolver {
 public:
  using Options = CholmodOptions;

  CholmodSolver();
  explicit CholmodSolver(const Options& options);
  /// analyze(a) then factorize().
  explicit CholmodSolver(const Eigen::SparseMatrix<double>& a, const Options& options = Options());
  ~CholmodSolver();
  CholmodSolver(const CholmodSolver&) = delete;
  CholmodSolver& operator=(const CholmodSolver&) = delete;
  CholmodSolver(CholmodSolver&&) noexcept;
  CholmodSolver& operator=(CholmodSolver&&) noexcept;

  /// Symbolic analysis (fill-reducing ordering) of the symmetric positive definite `a` (square; only the upper
  /// triangle is read). Throws surgsim::core::Error if CHOLMOD fails (e.g. out of memory).
  void analyze(const Eigen::SparseMatrix<double>& a);
  /// Bytes the numeric factor takes (after analyze: the exact supernodal size, known before factorizing).
  std::size_t factor_bytes() const;
  /// Numeric factorization. Throws surgsim::core::Error naming the column when `a` is not positive definite (for a
  /// stiffness matrix: a rigid mode is free or an element is inverted) or when memory runs out.
  void factorize();

  /// New values of the analysed matrix (the same pattern: throws surgsim::core::Error otherwise), then factorize(): the
  /// symbolic analysis is kept (a Newton loop refactoring its tangent, nonlinear/multirate.h).
  void refactorize(const Eigen::SparseMatrix<double>& a);

  bool factorized() const;
  int rows() const;
  /// CHOLMOD's reciprocal condition estimate of the factored matrix, (min / max diagonal of L)^2 (cholmod_rcond):
  /// cheap, a rough lower bound on 1 / cond(A) in the 1-norm. 0 before factorize().
  double rcond() const;

  /// x = A^-1 b for any number of columns (b and x: rows() x k; x must already have that size). Not thread-safe:
  /// CHOLMOD's workspace is reused between calls. Throws surgsim::core::Error on a size mismatch or CHOLMOD failure.
  void solve(const Eigen::Ref<const Eigen::MatrixXd>& b, Eigen::Ref<Eigen::MatrixXd> x);
  Eigen::MatrixXd solve(const Eigen::MatrixXd& b);

  /// Scratch of solve_unit_columns(): one per thread, reused between calls (grows to the largest block).
  struct UnitSolveWork {
    std::vector<double> x;    // rows() x count, column-major, in the factor's permuted row order
    std::vector<double> w;    // off-diagonal rows of a supernode x count
    std::vector<int> path;    // supernodes the unit right-hand sides reach in the forward solve
    std::vector<int> lo, hi;  // per supernode: first and last column whose forward solve reaches it
  };
  /// Position of row `row` of A in the factor's permuted order (x of solve_unit_columns is in that order).
  int permuted_row(int row) const;
  /// Supernodes holding these rows or an ancestor of them (the ones a backward solve must visit to get x at the
  /// rows); all supernodes when `rows` is empty. After factorize(), supernodal factor only.
  std::vector<char> supernodes_for_rows(const std::vector<int>& rows) const;
  /// x = A^-1 [e_rows[0] .. e_rows[count-1]] on the supernodal factor with our own BLAS calls: the forward solve
  /// visits only the supernodes each unit column reaches (and only the columns reaching them); the backward solve
  /// only the supernodes of `needed` (supernodes_for_rows; x is exact at the rows it was made from, unspecified
  /// elsewhere). Reads the factor only: several threads may call it at once, each with its own `work` (the precompute's
  /// threads). The result depends only on the factor and `rows` (same bits whatever the threads). Throws
  /// surgsim::core::Error before factorize() or on a simplicial factor.
  void solve_unit_columns(const int* rows, int count, const std::vector<char>& needed, UnitSolveWork& work) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace surgsim::fem
