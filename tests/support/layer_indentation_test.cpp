// hayes_kappa (tests/support/layer_indentation.h) against references that do not go through its Fredholm kernel:
// Sneddon's half space (a/h -> 0), the uniaxial-strain thin-layer limit (a/h >> 1), Hayes et al.'s published table
// (nu = 0.5), and an independent discretisation of the same contact problem done here (piecewise-constant pressure on
// annuli, collocation of the deflection, the half-space part in closed form by elliptic integrals).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include <Eigen/Dense>

#include "support/layer_indentation.h"

namespace {

using surgsim::test::hayes_force;
using surgsim::test::hayes_kappa;

const double kPi = std::acos(-1.0);

// (a) kappa -> 1 as a/h -> 0. The first correction is linear: kappa - 1 ~ (2/pi)(a/h) int_0^inf (1 - k(u)) du, about
// 0.9e-4 (nu = 0.3) and 1.03e-4 (nu = 0.45) at a/h = 1e-4, so "1 within 1e-4" holds there for nu = 0.3 only; the
// bound is 2e-4 at a/h = 1e-4 and 1e-5 at a/h = 1e-6, and kappa must exceed 1 (the base only stiffens).
TEST(LayerIndentation, HalfSpaceLimitIsSneddon) {
  for (const double nu : {0.0, 0.3, 0.45, 0.5}) {
    const double k4 = hayes_kappa(1e-4, nu), k6 = hayes_kappa(1e-6, nu);
    EXPECT_GT(k4, 1.0) << nu;
    EXPECT_NEAR(k4, 1.0, 2e-4) << nu;
    EXPECT_GT(k6, 1.0) << nu;
    EXPECT_NEAR(k6, 1.0, 1e-5) << nu;
  }
  // F = 2 a E delta / (1 - nu^2) for a 5 mm punch on 100 m of tissue (E = 3 kPa, nu = 0.45, 1 mm deep; a/h = 5e-5).
  const double sneddon = 2 * 0.005 * 3000.0 * 0.001 / (1 - 0.45 * 0.45);
  EXPECT_NEAR(hayes_force(0.005, 100.0, 3000.0, 0.45, 0.001) / sneddon, 1.0, 1e-4);
}

// kappa grows with a/h and with nu (a thinner or less compressible layer on the rigid base is stiffer).
TEST(LayerIndentation, MonotoneInThicknessAndPoisson) {
  double previous = 1.0;
  for (const double a_over_h : {0.05, 0.1, 0.2, 0.4, 1.0, 2.0}) {
    const double k = hayes_kappa(a_over_h, 0.45);
    EXPECT_GT(k, previous) << a_over_h;
    previous = k;
    EXPECT_LT(hayes_kappa(a_over_h, 0.3), k) << a_over_h;
  }
}

// (b) Thin layer (a >> h): under the punch the layer is in uniaxial strain, p = M delta / h with the P-wave modulus
// M = E (1 - nu) / ((1 + nu)(1 - 2 nu)), so F -> pi a^2 M delta / h, i.e. kappa -> (pi/2)(a/h)(1 - nu)^2 / (1 - 2 nu).
// The ring of layer within ~h of the punch edge carries extra load, so the true kappa is larger by a relative O(h/a):
// kappa / kappa_thin = 1 + beta h/a + ..., beta ~ 0.245 at nu = 0.3 (1.0246 at a/h = 10, 1.0122 at 20, 1.0061 at 40).
// Asserted: the ratio exceeds 1, is below 1 + 0.5 h/a, and the excess halves when a/h doubles (within 10 %).
TEST(LayerIndentation, ThinLayerLimitIsUniaxialStrain) {
  const double nu = 0.3;
  const auto ratio = [&](double a_over_h) {
    return hayes_kappa(a_over_h, nu) / (kPi / 2 * a_over_h * (1 - nu) * (1 - nu) / (1 - 2 * nu));
  };
  const double r10 = ratio(10.0), r20 = ratio(20.0);
  EXPECT_GT(r10, 1.0);
  EXPECT_LT(r10, 1.05);
  EXPECT_GT(r20, 1.0);
  EXPECT_LT(r20, 1.025);
  EXPECT_NEAR((r10 - 1) / (r20 - 1), 2.0, 0.2);
}

// (c) Hayes, Keer, Herrmann & Mockros 1972 (J. Biomech. 5:541-551), Table 1, the flat-ended indenter, nu = 0.5, a/h =
// 0.2 ... 2.0. The paper's table itself was not reachable here; the values are its nu = 0.5 ("instantaneous") column
// as transcribed in a public cartilage-analysis script (I. Kafian-Attari, 2021, MIT licence, Biomomentum Mach-1
// static moduli estimator, array poisson_inst_vals). They agree with hayes_kappa to 0.03 % at a/h = 0.2 and drift to
// 0.9 % at a/h = 2 (Hayes's 1972 values lie below; the annulus method below agrees with hayes_kappa to 1e-5 there,
// so the drift is the 1972 computation's). Asserted within 1 %. (The script's other column matches nu = 0.1 within
// 0.35 % except its a/h = 0.4 entry, 1.434, which is 1.5 % off; it does not name its nu, so it is not asserted.)
TEST(LayerIndentation, MatchesHayes1972TableAtNuOneHalf) {
  const double table[] = {1.281, 1.683, 2.211, 2.855, 3.609, 4.469, 5.441, 6.528, 7.735, 9.069};
  for (int i = 0; i < 10; ++i) {
    const double a_over_h = 0.2 * (i + 1);
    EXPECT_NEAR(hayes_kappa(a_over_h, 0.5) / table[i], 1.0, 0.01) << "a/h = " << a_over_h;
  }
}

// The independent method: the pressure is constant on each of n annuli r_{j-1} < r < r_j (a = 1, r_j = sin(pi j/2n),
// finer toward the edge), the deflection is collocated at the annuli's mid-radii. In units of 2 (1 - nu^2)/E the
// deflection of unit pressure on a disc of radius b is (2b/pi) E(r^2/b^2) inside and (2r/pi)[E(b^2/r^2) -
// (1 - b^2/r^2) K(b^2/r^2)] outside (half space; E, K of parameter m), minus the layer's correction
// int_0^inf P(xi) (1 - k(xi h)) J0(xi r) dxi with P(xi) = (r_j J1(xi r_j) - r_{j-1} J1(xi r_{j-1})) / xi, by
// Simpson's rule on [0, 26/h]. kappa = F / (4 a c) with w = c = 1. The discretisation error of kappa cancels largely
// in the ratio to the same annuli on the half space (which converges to 1); with 160 annuli the ratio is within 2e-5.
double kappa_by_annuli(double a_over_h, double nu, int n) {
  const double h = 1.0 / a_over_h, eta = 3 - 4 * nu;
  std::vector<double> edge(n + 1), mid(n);
  for (int j = 0; j <= n; ++j) edge[j] = std::sin(kPi / 2 * j / n);
  for (int i = 0; i < n; ++i) mid[i] = 0.5 * (edge[i] + edge[i + 1]);
  const auto disc = [](double r, double b) {
    if (b <= 0) return 0.0;
    if (r < b) return 2 * b / kPi * std::comp_ellint_2(r / b);  // comp_ellint_* take the modulus k = sqrt(m)
    const double k = b / r;
    return 2 * r / kPi * (std::comp_ellint_2(k) - (1 - k * k) * std::comp_ellint_1(k));
  };
  Eigen::MatrixXd half(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) half(i, j) = disc(mid[i], edge[j + 1]) - disc(mid[i], edge[j]);
  // The layer correction as (J0 .* weights) * P over the Simpson nodes.
  const int intervals = 1500;
  const double xi_max = 26.0 / h, step = xi_max / intervals;
  Eigen::MatrixXd j0w(n, intervals + 1), p(intervals + 1, n);
  for (int q = 0; q <= intervals; ++q) {
    const double xi = q * step, u = xi * h;
    const double k = (2 * eta * std::sinh(2 * u) - 4 * u) / (2 * eta * std::cosh(2 * u) + 1 + eta * eta + 4 * u * u);
    const double simpson = (q == 0 || q == intervals) ? 1.0 : (q % 2 ? 4.0 : 2.0);
    const double weight = step / 3 * simpson * (1 - k);
    for (int i = 0; i < n; ++i) j0w(i, q) = std::cyl_bessel_j(0.0, xi * mid[i]) * weight;
    for (int j = 0; j < n; ++j) {
      const double r1 = edge[j], r2 = edge[j + 1];
      p(q, j) = q == 0 ? 0.5 * (r2 * r2 - r1 * r1)
                       : (r2 * std::cyl_bessel_j(1.0, xi * r2) - r1 * std::cyl_bessel_j(1.0, xi * r1)) / xi;
    }
  }
  const Eigen::MatrixXd layer = half - j0w * p;
  const auto force = [&](const Eigen::MatrixXd& m) {
    const Eigen::VectorXd c = m.partialPivLu().solve(Eigen::VectorXd::Ones(n));
    double f = 0;
    for (int j = 0; j < n; ++j) f += c(j) * kPi * (edge[j + 1] * edge[j + 1] - edge[j] * edge[j]);
    return f;
  };
  return force(layer) / force(half);  // the common factor 1 / (4 a c) cancels
}

TEST(LayerIndentation, MatchesAnIndependentAnnulusDiscretisation) {
  struct Case {
    double a_over_h, nu;
  };
  for (const Case c : {Case{0.125, 0.45}, Case{0.4, 0.45}, Case{1.0, 0.3}, Case{2.0, 0.45}}) {
    const double reference = kappa_by_annuli(c.a_over_h, c.nu, 160);
    EXPECT_NEAR(hayes_kappa(c.a_over_h, c.nu) / reference, 1.0, 1e-4) << c.a_over_h << " " << c.nu;
  }
}

}  // namespace
