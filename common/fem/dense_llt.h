// The triangular solves of a dense Cholesky factor shared by the contact solves (Superposition, PatchSolver): the
// factor L in the lower triangle of a column-major array, leading dimension ld. Inline: they run in the haptic loop.
#pragma once
#include <Eigen/Core>

namespace surgsim::fem {

/// y <- (L L^T)^-1 y for the n x n factor L in the lower triangle of `a`. No allocation.
inline void llt_solve_in_place(const double* a, Eigen::Index ld, int n, double* y) noexcept {
  for (int j = 0; j < n; ++j) {
    const double* cj = a + j * ld;
    y[j] /= cj[j];
    for (int i = j + 1; i < n; ++i) y[i] -= cj[i] * y[j];
  }
  for (int j = n - 1; j >= 0; --j) {
    const double* cj = a + j * ld;
    double s = y[j];
    for (int i = j + 1; i < n; ++i) s -= cj[i] * y[i];
    y[j] = s / cj[j];
  }
}

}  // namespace surgsim::fem
