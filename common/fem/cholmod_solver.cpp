#include "fem/cholmod_solver.h"

#include <cholmod.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "core/error.h"

using namespace surgsim::core;

extern "C" {
// Fortran BLAS (the one CHOLMOD links: OpenBLAS on Debian through libblas.so.3).
void dgemm_(const char* ta, const char* tb, const int* m, const int* n, const int* k, const double* alpha,
            const double* a, const int* lda, const double* b, const int* ldb, const double* beta, double* c,
            const int* ldc);
void dtrsm_(const char* side, const char* uplo, const char* ta, const char* diag, const int* m, const int* n,
            const double* alpha, const double* a, const int* lda, double* b, const int* ldb);
}

namespace surgsim::fem {

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
  // Supernodal structure for solve_unit_columns (after factorize): inverse permutation, supernode of each permuted
  // row, parent supernode (-1 at a root).
  std::vector<int> pinv, super_of_row, parent;

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

void CholmodSolver::refactorize(const Eigen::SparseMatrix<double>& a) {
  Impl& s = *impl_;
  if (!s.l || !s.a) throw_error("CholmodSolver: refactorize() before analyze()");
  const int n = static_cast<int>(s.a->nrow);
  if (a.rows() != n || a.cols() != n)
    throw_error("CholmodSolver: refactorize() with a ", a.rows(), " x ", a.cols(), " matrix, analysed ", n);
  const auto* p = static_cast<const int*>(s.a->p);
  const auto* i = static_cast<const int*>(s.a->i);
  auto* v = static_cast<double*>(s.a->x);
  for (int j = 0; j < n; ++j) {
    int k = p[j];
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, j); it; ++it)
      if (it.row() <= j) {
        if (k >= p[j + 1] || i[k] != it.row())
          throw_error("CholmodSolver: refactorize() with another pattern (column ", j, ")");
        v[k++] = it.value();
      }
    if (k != p[j + 1]) throw_error("CholmodSolver: refactorize() with another pattern (column ", j, ")");
  }
  s.factorized = false;
  factorize();
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
    throw_error(
        "CHOLMOD: the matrix is not positive definite (failure at column ", s.l->minor, " of ", s.l->n,
        "); for a stiffness matrix this means a rigid mode is free (a part of the mesh not held by 3 non-collinear "
        "fixed nodes of its own, e.g. one joined to the rest only at a vertex or an edge) or an element is "
        "inverted");
  if (!ok || s.common.status < CHOLMOD_OK) s.fail("factorize");
  s.factorized = true;
  const int n = static_cast<int>(s.l->n);
  const auto* perm = static_cast<const int*>(s.l->Perm);
  s.pinv.assign(static_cast<std::size_t>(n), 0);
  for (int k = 0; k < n; ++k) s.pinv[static_cast<std::size_t>(perm[k])] = k;
  s.super_of_row.clear();
  s.parent.clear();
  if (s.l->is_super) {
    const int nsuper = static_cast<int>(s.l->nsuper);
    const auto* super = static_cast<const int*>(s.l->super);
    const auto* pi = static_cast<const int*>(s.l->pi);
    const auto* ls = static_cast<const int*>(s.l->s);
    s.super_of_row.resize(static_cast<std::size_t>(n));
    for (int k = 0; k < nsuper; ++k)
      for (int r = super[k]; r < super[k + 1]; ++r) s.super_of_row[static_cast<std::size_t>(r)] = k;
    s.parent.assign(static_cast<std::size_t>(nsuper), -1);
    for (int k = 0; k < nsuper; ++k) {
      const int nscol = super[k + 1] - super[k];
      if (pi[k + 1] - pi[k] > nscol)
        s.parent[static_cast<std::size_t>(k)] = s.super_of_row[static_cast<std::size_t>(ls[pi[k] + nscol])];
    }
  }
}

int CholmodSolver::permuted_row(int row) const { return impl_->pinv.at(static_cast<std::size_t>(row)); }

std::vector<char> CholmodSolver::supernodes_for_rows(const std::vector<int>& rows) const {
  const Impl& s = *impl_;
  if (!s.factorized || !s.l->is_super) throw_error("CholmodSolver: supernodes_for_rows() needs a supernodal factor");
  const std::size_t nsuper = s.parent.size();
  std::vector<char> mark(nsuper, rows.empty() ? 1 : 0);
  for (int r : rows)
    for (int k = s.super_of_row.at(static_cast<std::size_t>(s.pinv.at(static_cast<std::size_t>(r))));
         k >= 0 && !mark[static_cast<std::size_t>(k)]; k = s.parent[static_cast<std::size_t>(k)])
      mark[static_cast<std::size_t>(k)] = 1;
  return mark;
}

void CholmodSolver::solve_unit_columns(const int* rows, int count, const std::vector<char>& needed,
                                       UnitSolveWork& w) const {
  const Impl& s = *impl_;
  if (!s.factorized || !s.l->is_super || !s.l->is_ll)
    throw_error("CholmodSolver: solve_unit_columns() needs a supernodal LL' factor (factorize() first)");
  const int n = static_cast<int>(s.l->n);
  const int nsuper = static_cast<int>(s.l->nsuper);
  if (needed.size() != static_cast<std::size_t>(nsuper)) throw_error("CholmodSolver: supernode mask of the wrong size");
  const auto* super = static_cast<const int*>(s.l->super);
  const auto* pi = static_cast<const int*>(s.l->pi);
  const auto* px = static_cast<const int*>(s.l->px);
  const auto* ls = static_cast<const int*>(s.l->s);
  const auto* lx = static_cast<const double*>(s.l->x);
  const std::size_t nn = static_cast<std::size_t>(n);
  w.x.assign(nn * static_cast<std::size_t>(count), 0.0);
  w.lo.assign(static_cast<std::size_t>(nsuper), -1);
  w.hi.assign(static_cast<std::size_t>(nsuper), -1);
  w.path.clear();
  // The supernodes each unit column reaches: its own and its ancestors (the nonzeros of L^-1 e).
  for (int j = 0; j < count; ++j) {
    const int p = s.pinv.at(static_cast<std::size_t>(rows[j]));
    w.x[static_cast<std::size_t>(p) + nn * static_cast<std::size_t>(j)] = 1.0;
    for (int k = s.super_of_row[static_cast<std::size_t>(p)]; k >= 0; k = s.parent[static_cast<std::size_t>(k)]) {
      auto& lo = w.lo[static_cast<std::size_t>(k)];
      if (lo < 0) {
        lo = j;
        w.path.push_back(k);
      }
      w.hi[static_cast<std::size_t>(k)] = j;
    }
  }
  std::sort(w.path.begin(), w.path.end());
  const double one = 1.0, zero = 0.0, minus_one = -1.0;
  // Forward: L y = e, supernode by supernode on the columns that reach it.
  for (int k : w.path) {
    const int k1 = super[k], nscol = super[k + 1] - k1, nsrow = pi[k + 1] - pi[k], nrow2 = nsrow - nscol;
    const int c0 = w.lo[static_cast<std::size_t>(k)], nc = w.hi[static_cast<std::size_t>(k)] - c0 + 1;
    const double* l = lx + px[k];
    double* x1 = w.x.data() + k1 + nn * static_cast<std::size_t>(c0);
    dtrsm_("L", "L", "N", "N", &nscol, &nc, &one, l, &nsrow, x1, &n);
    if (nrow2 == 0) continue;
    w.w.resize(static_cast<std::size_t>(nrow2) * static_cast<std::size_t>(nc));
    dgemm_("N", "N", &nrow2, &nc, &nscol, &one, l + nscol, &nsrow, x1, &n, &zero, w.w.data(), &nrow2);
    const int* rs = ls + pi[k] + nscol;
    for (int j = 0; j < nc; ++j) {
      double* xj = w.x.data() + nn * static_cast<std::size_t>(c0 + j);
      const double* wj = w.w.data() + static_cast<std::size_t>(nrow2) * static_cast<std::size_t>(j);
      for (int i = 0; i < nrow2; ++i) xj[rs[i]] -= wj[i];
    }
  }
  // Backward: L' x = y over the needed supernodes (each needs only its ancestors, which are needed too).
  for (int k = nsuper - 1; k >= 0; --k) {
    if (!needed[static_cast<std::size_t>(k)]) continue;
    const int k1 = super[k], nscol = super[k + 1] - k1, nsrow = pi[k + 1] - pi[k], nrow2 = nsrow - nscol;
    const double* l = lx + px[k];
    double* x1 = w.x.data() + k1;
    if (nrow2 > 0) {
      w.w.resize(static_cast<std::size_t>(nrow2) * static_cast<std::size_t>(count));
      const int* rs = ls + pi[k] + nscol;
      for (int j = 0; j < count; ++j) {
        const double* xj = w.x.data() + nn * static_cast<std::size_t>(j);
        double* wj = w.w.data() + static_cast<std::size_t>(nrow2) * static_cast<std::size_t>(j);
        for (int i = 0; i < nrow2; ++i) wj[i] = xj[rs[i]];
      }
      dgemm_("T", "N", &nscol, &count, &nrow2, &minus_one, l + nscol, &nsrow, w.w.data(), &nrow2, &one, x1, &n);
    }
    dtrsm_("L", "L", "T", "N", &nscol, &count, &one, l, &nsrow, x1, &n);
  }
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

}  // namespace surgsim::fem
