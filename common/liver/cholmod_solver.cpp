#include "liver/cholmod_solver.h"

#include <cholmod.h>

#include <algorithm>
#include <cstring>

#include "core/error.h"

namespace surgsim {

struct CholmodSolver::Impl {
  Options options;
  cholmod_common common;
  cholmod_sparse* a = nullptr;
  cholmod_factor* l = nullptr;
  // cholmod_solve2 workspace, reused between blocks and calls.
  cholmod_dense* x = nullptr;
  cholmod_dense* y = nullptr;
  cholmod_dense* e = nullptr;
  bool factorized = false;

  explicit Impl(const Options& o) : options(o) {
    cholmod_start(&common);
    common.print = 0;  // we report failures ourselves
    common.supernodal = o.supernodal ? CHOLMOD_SUPERNODAL : CHOLMOD_SIMPLICIAL;
  }
  ~Impl() {
    cholmod_free_dense(&x, &common);
    cholmod_free_dense(&y, &common);
    cholmod_free_dense(&e, &common);
    cholmod_free_factor(&l, &common);
    cholmod_free_sparse(&a, &common);
    cholmod_finish(&common);
  }
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;

  [[noreturn]] void fail(const char* stage) const {
    if (common.status == CHOLMOD_OUT_OF_MEMORY)
      throw_error("CHOLMOD ", stage, ": out of memory (the matrix has ", a ? a->nrow : 0, " rows)");
    throw_error("CHOLMOD ", stage, " failed (status ", common.status, ")");
  }
};

CholmodSolver::CholmodSolver() : CholmodSolver(Options()) {}
CholmodSolver::CholmodSolver(const Options& options) : impl_(std::make_unique<Impl>(options)) {}
CholmodSolver::CholmodSolver(const Eigen::SparseMatrix<double>& a, const Options& options) : CholmodSolver(options) {
  analyze(a);
  factorize();
}
CholmodSolver::~CholmodSolver() = default;
CholmodSolver::CholmodSolver(CholmodSolver&&) noexcept = default;
CholmodSolver& CholmodSolver::operator=(CholmodSolver&&) noexcept = default;

void CholmodSolver::analyze(const Eigen::SparseMatrix<double>& a) {
  Impl& s = *impl_;
  if (a.rows() != a.cols()) throw_error("CholmodSolver: matrix is ", a.rows(), " x ", a.cols(), ", not square");
  cholmod_free_factor(&s.l, &s.common);
  cholmod_free_sparse(&s.a, &s.common);
  s.factorized = false;

  // Copy the upper triangle (stype = 1) into CHOLMOD's own storage.
  const int n = static_cast<int>(a.rows());
  std::size_t nnz = 0;
  for (int j = 0; j < n; ++j)
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, j); it; ++it)
      if (it.row() <= j) ++nnz;
  s.a = cholmod_allocate_sparse(static_cast<std::size_t>(n), static_cast<std::size_t>(n), nnz, 1, 1, 1, CHOLMOD_REAL,
                                &s.common);
  if (!s.a) s.fail("allocate");
  auto* p = static_cast<int*>(s.a->p);
  auto* i = static_cast<int*>(s.a->i);
  auto* v = static_cast<double*>(s.a->x);
  int k = 0;
  for (int j = 0; j < n; ++j) {
    p[j] = k;
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, j); it; ++it)
      if (it.row() <= j) {
        i[k] = static_cast<int>(it.row());
        v[k] = it.value();
        ++k;
      }
  }
  p[n] = k;
  s.l = cholmod_analyze(s.a, &s.common);
  if (!s.l || s.common.status < CHOLMOD_OK) s.fail("analyze");
}

std::size_t CholmodSolver::factor_bytes() const {
  const Impl& s = *impl_;
  if (!s.l) return 0;
  if (s.l->is_super) return s.l->xsize * sizeof(double) + s.l->ssize * sizeof(int);
  // Simplicial: cholmod_analyze counted the nonzeros of L.
  return static_cast<std::size_t>(s.common.lnz) * (sizeof(double) + sizeof(int));
}

void CholmodSolver::factorize() {
  Impl& s = *impl_;
  if (!s.l) throw_error("CholmodSolver: factorize() before analyze()");
  const int ok = cholmod_factorize(s.a, s.l, &s.common);
  if (s.common.status == CHOLMOD_NOT_POSDEF)
    throw_error("CHOLMOD: the matrix is not positive definite (failure at column ", s.l->minor, " of ", s.l->n,
                "); for a stiffness matrix this means a rigid mode is free (a part of the mesh not held by 3 non-collinear "
                "fixed nodes of its own, e.g. one joined to the rest only at a vertex or an edge) or an element is "
                "inverted");
  if (!ok || s.common.status < CHOLMOD_OK) s.fail("factorize");
  s.factorized = true;
}

bool CholmodSolver::factorized() const { return impl_->factorized; }
int CholmodSolver::rows() const { return impl_->a ? static_cast<int>(impl_->a->nrow) : 0; }

double CholmodSolver::rcond() const {
  Impl& s = *impl_;
  return s.factorized ? cholmod_rcond(s.l, &s.common) : 0.0;
}

void CholmodSolver::solve(const Eigen::Ref<const Eigen::MatrixXd>& b, Eigen::Ref<Eigen::MatrixXd> x) {
  Impl& s = *impl_;
  if (!s.factorized) throw_error("CholmodSolver: solve() before factorize()");
  const Eigen::Index n = rows();
  if (b.rows() != n || x.rows() != n || x.cols() != b.cols())
    throw_error("CholmodSolver: solve sizes: A is ", n, " x ", n, ", b is ", b.rows(), " x ", b.cols(), ", x is ",
                x.rows(), " x ", x.cols());
  const Eigen::Index block = std::max(1, s.options.block_columns);
  for (Eigen::Index c0 = 0; c0 < b.cols(); c0 += block) {
    const Eigen::Index nc = std::min(block, b.cols() - c0);
    // View of the block of b as a cholmod_dense (read only; CHOLMOD does not write B).
    cholmod_dense bd;
    std::memset(&bd, 0, sizeof(bd));
    bd.nrow = static_cast<std::size_t>(n);
    bd.ncol = static_cast<std::size_t>(nc);
    bd.d = static_cast<std::size_t>(b.outerStride());
    bd.nzmax = bd.d * bd.ncol;
    bd.x = const_cast<double*>(b.data() + c0 * b.outerStride());
    bd.xtype = CHOLMOD_REAL;
    bd.dtype = CHOLMOD_DOUBLE;
    if (!cholmod_solve2(CHOLMOD_A, s.l, &bd, nullptr, &s.x, nullptr, &s.y, &s.e, &s.common)) s.fail("solve");
    const double* xs = static_cast<const double*>(s.x->x);
    for (Eigen::Index c = 0; c < nc; ++c)
      x.col(c0 + c) = Eigen::Map<const Eigen::VectorXd>(xs + c * static_cast<Eigen::Index>(s.x->d), n);
  }
}

Eigen::MatrixXd CholmodSolver::solve(const Eigen::MatrixXd& b) {
  Eigen::MatrixXd x(b.rows(), b.cols());
  solve(b, x);
  return x;
}

}  // namespace surgsim
