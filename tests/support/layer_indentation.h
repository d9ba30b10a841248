// The analytic reference for a rigid, frictionless, flat-ended cylindrical punch (radius a) pressed delta deep into an
// elastic layer (thickness h, E, nu) bonded to a rigid base: F = 2 a E delta / (1 - nu^2) * kappa(a/h, nu) (Hayes,
// Keer, Herrmann & Mockros 1972, "A mathematical analysis for indentation tests of articular cartilage", J. Biomech.
// 5:541-551; the integral equation is Lebedev & Ufliand's, PMM 22, 1958). kappa -> 1 as a/h -> 0 (Sneddon's half
// space, F = 2 a E delta / (1 - nu^2)); kappa > 1 for every a/h > 0 (the rigid base stiffens the layer).
//
// Derivation (z into the layer, surface z = 0 shear-free, base z = h: u = 0). With P(xi) = int_0^a p(r) r J0(xi r) dr
// the Hankel transform of the contact pressure, the surface deflection is
//   w(r) = 2 (1 - nu^2) / E * int_0^inf P(xi) k(xi h) J0(xi r) dxi,
//   k(u) = (2 eta sinh 2u - 4u) / (2 eta cosh 2u + 1 + eta^2 + 4u^2),   eta = 3 - 4 nu,
// k -> 1 as u -> inf (the half space) and k ~ u (1 - 2 nu) / (2 (1 - nu)^2) as u -> 0 (uniaxial strain of a thin
// layer: w = p h (1 + nu)(1 - 2 nu) / (E (1 - nu))). Write the pressure through Copson's representation
// P(xi) = int_0^a g(t) cos(xi t) dt, and J0(xi r) = (2/pi) int_0^r cos(xi t) / sqrt(r^2 - t^2) dt. Because
// int_0^inf cos(xi t) J0(xi r) dxi = 1 / sqrt(r^2 - t^2) for t < r and 0 for t > r, the condition w = delta on r < a
// becomes an Abel equation int_0^r G(t) / sqrt(r^2 - t^2) dt = c, c = E delta / (2 (1 - nu^2)), whose solution is
// G = 2 c / pi, with G(t) = g(t) - (2/pi) int_0^a g(s) int_0^inf (1 - k(xi h)) cos(xi s) cos(xi t) dxi ds. With
// g(a tau) = (2 c / pi) phi(tau), s = a sigma, xi = u / h and lambda = a / h this is the Fredholm equation of the
// second kind
//   phi(tau) - int_0^1 K(tau, sigma) phi(sigma) dsigma = 1,   0 <= tau <= 1,
//   K(tau, sigma) = (2/pi) lambda int_0^inf (1 - k(u)) cos(lambda u tau) cos(lambda u sigma) du,
// and the force F = 2 pi P(0) = 2 pi int_0^a g dt = 4 a c int_0^1 phi = 2 a E delta / (1 - nu^2) * kappa with
// kappa = int_0^1 phi(tau) dtau. The sign: 0 < k < 1, so K > 0 on the diagonal and phi > 1, kappa > 1.
// 1 - k(u) = (1 + eta^2 + 4u + 4u^2 + 2 eta e^{-2u}) / (2 eta cosh 2u + 1 + eta^2 + 4u^2) (no cancellation), equal to
// 1 at u = 0 and decaying like 4 u^2 e^{-2u} / eta.
//
// Numerics: Nystrom on Gauss-Legendre nodes of [0, 1] (more nodes as lambda grows: the kernel's width in tau is
// ~1/lambda); the u integral on [0, 24] (1 - k is below 1e-17 beyond) by composite 16-point Gauss-Legendre on panels
// of at most 0.5 and at most pi/lambda (one period of the fastest cosine, cos(2 lambda u)), far below 1e-6.
// K = (2/pi) lambda C W C^T with C(i, q) = cos(lambda u_q tau_i), W = diag(w_q (1 - k(u_q))). kappa is unchanged to
// 1e-10 by doubling the Nystrom nodes and taking u to 40 (a/h = 0.125 ... 20). Checked independently: k(u) against a
// Papkovich-Neuber solution of the layer (12 digits), kappa against a piecewise-constant-pressure annulus collocation
// (1e-6; layer_indentation_test.cpp has a coarser copy) and Hayes's table (nu = 0.5, within 0.9 %).
#pragma once
#include <cmath>
#include <vector>

#include <Eigen/Dense>

namespace surgsim::test {

namespace layer_detail {

/// The n-point Gauss-Legendre rule on [lo, hi] appended to x and w (Newton on P_n from Chebyshev guesses).
inline void gauss_legendre(int n, double lo, double hi, std::vector<double>& x, std::vector<double>& w) {
  const double pi = std::acos(-1.0);
  for (int i = 0; i < n; ++i) {
    double z = std::cos(pi * (i + 0.75) / (n + 0.5));
    double dp = 1.0;
    for (int it = 0; it < 100; ++it) {
      double p0 = 1.0, p1 = z;  // P_0, P_1; after the loop p1 = P_n(z), p0 = P_{n-1}(z)
      for (int k = 2; k <= n; ++k) {
        const double p2 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      dp = n * (z * p1 - p0) / (z * z - 1.0);
      const double dz = p1 / dp;
      z -= dz;
      if (std::abs(dz) < 1e-15) break;
    }
    x.push_back(0.5 * (lo + hi) + 0.5 * (hi - lo) * z);
    w.push_back((hi - lo) / ((1.0 - z * z) * dp * dp));
  }
}

/// 1 - k(u) for the layer bonded to a rigid base, eta = 3 - 4 nu (written without cancellation).
inline double one_minus_layer_function(double u, double eta) {
  const double num = 1.0 + eta * eta + 4.0 * u + 4.0 * u * u + 2.0 * eta * std::exp(-2.0 * u);
  const double den = 2.0 * eta * std::cosh(2.0 * u) + 1.0 + eta * eta + 4.0 * u * u;
  return num / den;
}

}  // namespace layer_detail

/// kappa(a/h, nu) of Hayes et al. 1972 for the flat-ended punch on a bonded layer (see the derivation above).
/// nodes = 0 chooses the Nystrom node count from a/h; nodes > 0 forces it (convergence checks).
inline double hayes_kappa(double a_over_h, double nu, int nodes = 0, double u_max = 24.0) {
  const double lambda = a_over_h;
  if (lambda <= 0.0) return 1.0;
  const double pi = std::acos(-1.0);
  const double eta = 3.0 - 4.0 * nu;
  const int n = nodes > 0 ? nodes : 32 + static_cast<int>(std::ceil(12.0 * lambda));
  std::vector<double> t, tw;
  layer_detail::gauss_legendre(n, 0.0, 1.0, t, tw);
  // The u rule: composite 16-point Gauss-Legendre on [0, u_max].
  const double panel = lambda < 2.0 * pi ? 0.5 : pi / lambda;
  const int panels = static_cast<int>(std::ceil(u_max / panel));
  std::vector<double> u, uw;
  for (int p = 0; p < panels; ++p)
    layer_detail::gauss_legendre(16, p * u_max / panels, (p + 1) * u_max / panels, u, uw);
  const int m = static_cast<int>(u.size());
  Eigen::MatrixXd c(n, m);
  Eigen::VectorXd wf(m);
  for (int q = 0; q < m; ++q) {
    wf(q) = uw[q] * layer_detail::one_minus_layer_function(u[q], eta);
    for (int i = 0; i < n; ++i) c(i, q) = std::cos(lambda * u[q] * t[i]);
  }
  const Eigen::MatrixXd k = (2.0 / pi) * lambda * (c * wf.asDiagonal() * c.transpose());
  // Nystrom: phi_i - sum_j K(t_i, t_j) w_j phi_j = 1.
  Eigen::MatrixXd a = Eigen::MatrixXd::Identity(n, n);
  for (int j = 0; j < n; ++j) a.col(j) -= k.col(j) * tw[j];
  const Eigen::VectorXd phi = a.partialPivLu().solve(Eigen::VectorXd::Ones(n));
  double kappa = 0.0;
  for (int i = 0; i < n; ++i) kappa += tw[i] * phi(i);
  return kappa;
}

/// The force (N) on a flat punch of radius a (m) pressed delta (m) into a layer of thickness h (m), E (Pa), nu,
/// bonded to a rigid base: F = 2 a E delta / (1 - nu^2) * kappa(a/h, nu).
inline double hayes_force(double a, double h, double e, double nu, double delta) {
  return 2.0 * a * e * delta / (1.0 - nu * nu) * hayes_kappa(a / h, nu);
}

}  // namespace surgsim::test
