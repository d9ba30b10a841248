#include "intestine/mass_spring.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>

#include "support/alloc_counter.h"
#include "core/error.h"
#include "intestine/intestine_model.h"

using namespace surgsim::core;
using namespace surgsim::intestine;

namespace surgsim::intestine {
namespace {

IntestineParams small_params() {
  IntestineParams p;
  p.columns = 8;
  p.rows = 3;
  p.length = 1.2;
  p.folds = 1;
  return p;
}

// Rest shape + a seeded random displacement (m) and velocity (m/s) of the free nodes.
void perturb(const MassSpring& sys, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, double dx, double dv, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  x = sys.rest();
  v.setZero(3, sys.node_count());
  for (int i = 0; i < sys.node_count(); ++i) {
    if (sys.fixed(i)) continue;
    for (int c = 0; c < 3; ++c) {
      x(c, i) += dx * u(rng);
      v(c, i) = dv * u(rng);
    }
  }
}

// Independent dense implementation of the linearized backward Euler step, to check the banded one.
void dense_implicit_step(const MassSpring& sys, const std::vector<PenaltyContact>& contacts, double h,
                         Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v) {
  const int n = sys.node_count();
  std::vector<int> dof(static_cast<std::size_t>(n), -1);
  int f = 0;
  for (int i = 0; i < n; ++i) dof[static_cast<std::size_t>(i)] = sys.fixed(i) ? -1 : f++;
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(3 * n, 3 * n), D = Eigen::MatrixXd::Zero(3 * n, 3 * n);
  Eigen::VectorXd force = Eigen::VectorXd::Zero(3 * n), vel(3 * n);
  for (int i = 0; i < n; ++i) vel.segment<3>(3 * i) = v.col(i);
  for (int i = 0; i < n; ++i) {
    const double m = sys.mass()[static_cast<std::size_t>(i)];
    force.segment<3>(3 * i) = m * sys.gravity() - sys.drag() * m * v.col(i);
    D.block<3, 3>(3 * i, 3 * i) -= sys.drag() * m * Eigen::Matrix3d::Identity();
  }
  for (const Spring& s : sys.springs()) {
    const Eigen::Vector3d d = x.col(s.j) - x.col(s.i);
    const double l = d.norm();
    const Eigen::Vector3d u = d / l;
    const Eigen::Matrix3d uu = u * u.transpose();
    const Eigen::Vector3d fi = (s.stiffness * (l - s.rest) + s.damping * (v.col(s.j) - v.col(s.i)).dot(u)) * u;
    force.segment<3>(3 * s.i) += fi;
    force.segment<3>(3 * s.j) -= fi;
    const double t = std::max(0.0, 1 - s.rest / l);
    const Eigen::Matrix3d ks = s.stiffness * (uu + t * (Eigen::Matrix3d::Identity() - uu));
    for (int a : {s.i, s.j}) {
      for (int b : {s.i, s.j}) {
        const double sign = a == b ? -1.0 : 1.0;
        K.block<3, 3>(3 * a, 3 * b) += sign * ks;
        D.block<3, 3>(3 * a, 3 * b) += sign * s.damping * uu;
      }
    }
  }
  for (const PenaltyContact& c : contacts) {
    for (int a = 0; a < c.count; ++a) {
      force.segment<3>(3 * c.nodes[a]) += c.weights[a] * c.stiffness * c.depth * c.normal;
      for (int b = 0; b < c.count; ++b) {
        K.block<3, 3>(3 * c.nodes[a], 3 * c.nodes[b]) -=
            c.stiffness * c.weights[a] * c.weights[b] * c.normal * c.normal.transpose();
      }
    }
  }
  // Restrict to the free dofs.
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(3 * f, 3 * f);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(3 * f);
  const Eigen::VectorXd kv = K * vel;
  for (int i = 0; i < n; ++i) {
    const int di = dof[static_cast<std::size_t>(i)];
    if (di < 0) continue;
    rhs.segment<3>(3 * di) = h * (force.segment<3>(3 * i) + h * kv.segment<3>(3 * i));
    A.block<3, 3>(3 * di, 3 * di) += sys.mass()[static_cast<std::size_t>(i)] * Eigen::Matrix3d::Identity();
    for (int j = 0; j < n; ++j) {
      const int dj = dof[static_cast<std::size_t>(j)];
      if (dj < 0) continue;
      A.block<3, 3>(3 * di, 3 * dj) -= h * D.block<3, 3>(3 * i, 3 * j) + h * h * K.block<3, 3>(3 * i, 3 * j);
    }
  }
  const Eigen::VectorXd dv = A.ldlt().solve(rhs);
  for (int i = 0; i < n; ++i) {
    const int di = dof[static_cast<std::size_t>(i)];
    if (di < 0) continue;
    v.col(i) += dv.segment<3>(3 * di);
    x.col(i) += h * v.col(i);
  }
}

TEST(MassSpringTest, ImplicitStepMatchesDenseReference) {
  const IntestineModel model(small_params());
  const MassSpring& sys = model.mass_spring();
  EXPECT_EQ(sys.node_band(), 2 * (model.rows() - 1));  // bending springs c, c + 2 set the band
  Eigen::Matrix3Xd x, v;
  perturb(sys, x, v, 0.01, 0.2, 1);
  // Two penalty contacts: one on a segment (coupled nodes), one on a triangle touching a fixed node.
  std::vector<PenaltyContact> contacts(2);
  contacts[0].count = 2;
  contacts[0].nodes = {model.node(0, 3), model.node(0, 4), -1};
  contacts[0].weights = {0.3, 0.7, 0};
  contacts[0].normal = Eigen::Vector3d(0.2, -0.5, 1).normalized();
  contacts[0].depth = 0.004;
  contacts[0].stiffness = 500;
  contacts[1].count = 3;
  contacts[1].nodes = {model.node(1, 2), model.node(2, 2), model.node(1, 3)};
  contacts[1].weights = {0.2, 0.5, 0.3};
  contacts[1].normal = Eigen::Vector3d(1, 0.3, 0).normalized();
  contacts[1].depth = 0.002;
  contacts[1].stiffness = 800;

  Eigen::Matrix3Xd xr = x, vr = v;
  dense_implicit_step(sys, contacts, 1e-3, xr, vr);
  MassSpringWorkspace work(sys);
  ASSERT_EQ(integrate(sys, Integrator::kImplicitEuler, contacts.data(), 2, 1e-3, x, v, work), IntegrateStatus::kOk);
  EXPECT_LT((v - vr).cwiseAbs().maxCoeff(), 1e-10 * (1 + vr.cwiseAbs().maxCoeff()));
  EXPECT_LT((x - xr).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_GT(work.min_pivot(), 0);
  EXPECT_GE(work.max_pivot(), work.min_pivot());
}

TEST(MassSpringTest, SymplecticStepIsExplicit) {
  const IntestineModel model(small_params());
  const MassSpring& sys = model.mass_spring();
  Eigen::Matrix3Xd x, v;
  perturb(sys, x, v, 0.01, 0.1, 2);
  // The force at (x, v) from the dense reference's terms: a zero-step implicit gives f / m as (dv / h) for h -> 0.
  const Eigen::Matrix3Xd x0 = x, v0 = v;
  MassSpringWorkspace work(sys);
  const double h = 1e-4;
  ASSERT_EQ(integrate(sys, Integrator::kSymplecticEuler, nullptr, 0, h, x, v, work), IntegrateStatus::kOk);
  // x1 = x0 + h v1 exactly, fixed nodes unmoved.
  for (int i = 0; i < sys.node_count(); ++i) {
    if (sys.fixed(i)) {
      EXPECT_EQ(x.col(i), x0.col(i));
      EXPECT_EQ(v.col(i), Eigen::Vector3d::Zero());
    } else {
      EXPECT_LT((x.col(i) - (x0.col(i) + h * v.col(i))).norm(), 1e-15);
    }
  }
  // v1 - v0 agrees with the implicit step's to first order in h.
  Eigen::Matrix3Xd xi = x0, vi = v0;
  ASSERT_EQ(integrate(sys, Integrator::kImplicitEuler, nullptr, 0, h, xi, vi, work), IntegrateStatus::kOk);
  EXPECT_LT(((v - v0) - (vi - v0)).cwiseAbs().maxCoeff(), 0.05 * (v - v0).cwiseAbs().maxCoeff());
}

// Total energy over a run from a perturbed rest shape, all springs at stiffness k; returns the largest E(t) - E(0)
// relative to the initial elastic + kinetic energy, or +inf if the run blew up.
double energy_growth(Integrator integrator, double k, int steps, int* blowup_step = nullptr) {
  IntestineParams p;
  p.structural_stiffness = p.shear_stiffness = p.bending_stiffness = k;
  const IntestineModel model(p);
  const MassSpring& sys = model.mass_spring();
  Eigen::Matrix3Xd x, v;
  perturb(sys, x, v, 0.002, 0.05, 3);
  MassSpringWorkspace work(sys);
  const double e0 = sys.kinetic_energy(v) + sys.potential_energy(x);
  const double scale = sys.kinetic_energy(v) + sys.potential_energy(x) - sys.potential_energy(sys.rest());
  double worst = 0;
  for (int s = 0; s < steps; ++s) {
    const IntegrateStatus st = integrate(sys, integrator, nullptr, 0, 1e-3, x, v, work);
    const double e = sys.kinetic_energy(v) + sys.potential_energy(x);
    if (st != IntegrateStatus::kOk || !std::isfinite(e) || e - e0 > 1e6 * std::abs(scale)) {
      if (blowup_step) *blowup_step = s;
      return std::numeric_limits<double>::infinity();
    }
    worst = std::max(worst, (e - e0) / std::abs(scale));
  }
  return worst;
}

TEST(MassSpringTest, ImplicitEnergyStaysBoundedForStiffSpringsAtOneMillisecond) {
  for (double k : {1e2, 1e3, 1e4, 1e5, 1e6}) {
    const double growth = energy_growth(Integrator::kImplicitEuler, k, 600);
    EXPECT_LE(growth, 0.01) << "k = " << k << " N/m";  // dissipative: never above the initial energy
  }
}

TEST(MassSpringTest, ExplicitBlowsUpAtTheStiffEnd) {
  // Soft springs: the explicit step is stable at 1 ms (omega h << 2).
  EXPECT_LT(energy_growth(Integrator::kSymplecticEuler, 1e2, 600), 0.05);
  // Stiff springs: omega_max h >> 2, the energy explodes within a few dozen steps; the implicit step does not.
  for (double k : {1e5, 1e6}) {
    int at = -1;
    EXPECT_EQ(energy_growth(Integrator::kSymplecticEuler, k, 600, &at), std::numeric_limits<double>::infinity())
        << "k = " << k;
    EXPECT_GE(at, 0);
    EXPECT_LT(at, 200) << "k = " << k;
  }
}

TEST(MassSpringTest, NonFiniteInputIsRefusedAndTheStateRestored) {
  const IntestineModel model(small_params());
  const MassSpring& sys = model.mass_spring();
  Eigen::Matrix3Xd x, v;
  perturb(sys, x, v, 0.01, 0.1, 4);
  const Eigen::Matrix3Xd x0 = x, v0 = v;
  MassSpringWorkspace work(sys);
  PenaltyContact bad;
  bad.count = 1;
  bad.nodes = {model.node(0, 2), -1, -1};
  bad.weights = {1, 0, 0};
  bad.depth = std::numeric_limits<double>::quiet_NaN();
  bad.stiffness = 100;
  for (Integrator in : {Integrator::kImplicitEuler, Integrator::kSymplecticEuler}) {
    EXPECT_EQ(integrate(sys, in, &bad, 1, 1e-3, x, v, work), IntegrateStatus::kNonFinite);
    EXPECT_EQ(x, x0);
    EXPECT_EQ(v, v0);
    EXPECT_EQ(integrate(sys, in, nullptr, 0, std::numeric_limits<double>::quiet_NaN(), x, v, work),
              IntegrateStatus::kNonFinite);
    EXPECT_EQ(x, x0);
  }
  // An explicit step far beyond its stability limit overflows to infinity: refused, state restored.
  IntestineParams p = small_params();
  p.structural_stiffness = 1e12;
  const IntestineModel stiff(p);
  MassSpringWorkspace w2(stiff.mass_spring());
  Eigen::Matrix3Xd xs, vs;
  perturb(stiff.mass_spring(), xs, vs, 0.01, 0.1, 5);
  IntegrateStatus last = IntegrateStatus::kOk;
  for (int s = 0; s < 200 && last == IntegrateStatus::kOk; ++s) {
    last = integrate(stiff.mass_spring(), Integrator::kSymplecticEuler, nullptr, 0, 1e-2, xs, vs, w2);
  }
  EXPECT_EQ(last, IntegrateStatus::kNonFinite);
  EXPECT_TRUE(xs.allFinite());
  EXPECT_TRUE(vs.allFinite());
}

TEST(MassSpringTest, IntegrateAllocatesNothing) {
  const IntestineModel model(IntestineParams{});
  const MassSpring& sys = model.mass_spring();
  Eigen::Matrix3Xd x, v;
  perturb(sys, x, v, 0.005, 0.1, 6);
  MassSpringWorkspace work(sys);
  PenaltyContact c;
  c.count = 2;
  c.nodes = {model.node(0, 10), model.node(0, 11), -1};
  c.weights = {0.5, 0.5, 0};
  c.depth = 0.003;
  c.stiffness = 300;
  surgsim::test::AllocationCounter counter;
  for (int s = 0; s < 20; ++s) {
    integrate(sys, Integrator::kImplicitEuler, &c, 1, 1e-3, x, v, work);
    integrate(sys, Integrator::kSymplecticEuler, &c, 1, 1e-4, x, v, work);
  }
  EXPECT_EQ(counter.count(), 0);
}

TEST(MassSpringTest, RejectsBadSystems) {
  Eigen::Matrix3Xd rest(3, 3);
  rest << 0, 1, 2, 0, 0, 0, 0, 0, 0;
  const std::vector<double> mass{1, 1, 1};
  const std::vector<std::uint8_t> fixed{1, 0, 0};
  const Eigen::Vector3d g(0, 0, -9.81);
  EXPECT_NO_THROW(MassSpring(rest, mass, fixed, {Spring{0, 1, 1, 10, 0}, Spring{1, 2, 1, 10, 0}}, g, 0));
  EXPECT_THROW(MassSpring(rest, mass, fixed, {Spring{0, 3, 1, 10, 0}}, g, 0), Error);      // bad node
  EXPECT_THROW(MassSpring(rest, mass, fixed, {Spring{0, 1, 0, 10, 0}}, g, 0), Error);      // zero rest length
  EXPECT_THROW(MassSpring(rest, mass, fixed, {Spring{0, 1, 1, -1, 0}}, g, 0), Error);      // negative stiffness
  EXPECT_THROW(MassSpring(rest, {1, 0, 1}, fixed, {}, g, 0), Error);                      // massless free node
  EXPECT_THROW(MassSpring(rest, mass, fixed, {}, g, 0, {0, 0, 0}), Error);                // not a permutation
  EXPECT_THROW(MassSpring(rest, mass, fixed, {}, g, -1), Error);                          // negative drag
}

}  // namespace
}  // namespace surgsim::intestine
