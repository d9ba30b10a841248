#include "intestine/mass_spring.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "core/error.h"

namespace surgsim::intestine {

const char* to_string(Integrator integrator) {
  switch (integrator) {
    case Integrator::kImplicitEuler: return "implicit Euler";
    case Integrator::kSymplecticEuler: return "symplectic Euler";
  }
  return "?";
}

const char* to_string(IntegrateStatus status) {
  switch (status) {
    case IntegrateStatus::kOk: return "ok";
    case IntegrateStatus::kNonFinite: return "non-finite value";
    case IntegrateStatus::kNotPositive: return "implicit matrix not positive definite";
  }
  return "?";
}

MassSpring::MassSpring(Eigen::Matrix3Xd rest, std::vector<double> mass, std::vector<std::uint8_t> fixed,
                       std::vector<Spring> springs, const Eigen::Vector3d& gravity, double drag,
                       std::vector<int> order)
    : rest_(std::move(rest)),
      mass_(std::move(mass)),
      fixed_(std::move(fixed)),
      springs_(std::move(springs)),
      gravity_(gravity),
      drag_(drag) {
  const int n = static_cast<int>(rest_.cols());
  const auto un = static_cast<std::size_t>(n);
  if (n == 0) throw_error("mass-spring: no nodes");
  if (mass_.size() != un || fixed_.size() != un) throw_error("mass-spring: mass and fixed need one entry per node");
  if (!rest_.allFinite() || !gravity_.allFinite() || !std::isfinite(drag_) || drag_ < 0) {
    throw_error("mass-spring: non-finite rest shape or gravity, or negative drag");
  }
  inv_mass_.assign(un, 0.0);
  for (int i = 0; i < n; ++i) {
    const auto ui = static_cast<std::size_t>(i);
    if (fixed_[ui]) continue;
    if (!(mass_[ui] > 0) || !std::isfinite(mass_[ui])) throw_error("mass-spring: node ", i, " has mass ", mass_[ui]);
    inv_mass_[ui] = 1.0 / mass_[ui];
  }
  // Band slots: the caller's order or the natural order of the free nodes.
  slot_.assign(un, -1);
  for (int i = 0; i < n; ++i) free_count_ += fixed_[static_cast<std::size_t>(i)] ? 0 : 1;
  node_of_slot_.assign(static_cast<std::size_t>(free_count_), -1);
  int next = 0;
  for (int i = 0; i < n; ++i) {
    const auto ui = static_cast<std::size_t>(i);
    if (fixed_[ui]) continue;
    const int s = order.empty() ? next++ : order[ui];
    if (order.size() != 0 && order.size() != un) throw_error("mass-spring: order needs one entry per node");
    if (s < 0 || s >= free_count_ || node_of_slot_[static_cast<std::size_t>(s)] != -1) {
      throw_error("mass-spring: order is not a permutation of the free nodes (node ", i, " -> slot ", s, ")");
    }
    slot_[ui] = s;
    node_of_slot_[static_cast<std::size_t>(s)] = i;
  }
  // Springs: valid nodes, positive rest length and stiffness; the band is the widest free-free coupling.
  for (const Spring& sp : springs_) {
    if (sp.i < 0 || sp.j < 0 || sp.i >= n || sp.j >= n || sp.i == sp.j) {
      throw_error("mass-spring: spring (", sp.i, ", ", sp.j, ") has invalid nodes");
    }
    if (!(sp.rest > 0) || !(sp.stiffness >= 0) || !(sp.damping >= 0) || !std::isfinite(sp.stiffness) ||
        !std::isfinite(sp.damping)) {
      throw_error("mass-spring: spring (", sp.i, ", ", sp.j, ") has rest ", sp.rest, " m, stiffness ", sp.stiffness,
                  " N/m, damping ", sp.damping, " N s/m");
    }
    const int a = slot_[static_cast<std::size_t>(sp.i)], b = slot_[static_cast<std::size_t>(sp.j)];
    if (a >= 0 && b >= 0) node_band_ = std::max(node_band_, std::abs(a - b));
  }
  // Envelope: the lowest slot each slot couples to, made non-decreasing (then the fill of the factorization stays
  // inside it and every column's rows are contiguous), and the last row of every column.
  const auto uf = static_cast<std::size_t>(free_count_);
  first_slot_.resize(uf);
  for (int s = 0; s < free_count_; ++s) first_slot_[static_cast<std::size_t>(s)] = s;
  for (const Spring& sp : springs_) {
    const int a = slot_[static_cast<std::size_t>(sp.i)], b = slot_[static_cast<std::size_t>(sp.j)];
    if (a < 0 || b < 0) continue;
    int& f = first_slot_[static_cast<std::size_t>(std::max(a, b))];
    f = std::min(f, std::min(a, b));
  }
  for (int s = free_count_ - 2; s >= 0; --s) {
    first_slot_[static_cast<std::size_t>(s)] =
        std::min(first_slot_[static_cast<std::size_t>(s)], first_slot_[static_cast<std::size_t>(s + 1)]);
  }
  last_slot_.resize(uf);
  for (int s = 0; s < free_count_; ++s) {
    last_slot_[static_cast<std::size_t>(s)] = s;
    for (int k = first_slot_[static_cast<std::size_t>(s)]; k < s; ++k) last_slot_[static_cast<std::size_t>(k)] = s;
  }
  panel_offset_.assign(uf + 1, 0);
  for (int s = 0; s < free_count_; ++s) {
    const auto us = static_cast<std::size_t>(s);
    panel_offset_[us + 1] = panel_offset_[us] + 9 * static_cast<std::size_t>(last_slot_[us] - s + 1);
  }
}

double MassSpring::potential_energy(const Eigen::Matrix3Xd& x) const {
  double e = 0;
  for (const Spring& sp : springs_) {
    const double stretch = (x.col(sp.j) - x.col(sp.i)).norm() - sp.rest;
    e += 0.5 * sp.stiffness * stretch * stretch;
  }
  for (int i = 0; i < node_count(); ++i) {
    if (!fixed(i)) e -= mass_[static_cast<std::size_t>(i)] * gravity_.dot(x.col(i));
  }
  return e;
}

double MassSpring::kinetic_energy(const Eigen::Matrix3Xd& v) const {
  double e = 0;
  for (int i = 0; i < node_count(); ++i) e += 0.5 * mass_[static_cast<std::size_t>(i)] * v.col(i).squaredNorm();
  return e;
}

MassSpringWorkspace::MassSpringWorkspace(const MassSpring& system) {
  factor_.assign(system.factor_size(), 0.0);
  rhs_.assign(3 * static_cast<std::size_t>(system.free_count()), 0.0);
  force_.setZero(3, system.node_count());
  x0_.setZero(3, system.node_count());
  v0_.setZero(3, system.node_count());
}

namespace {

bool finite(const Eigen::Matrix3Xd& m) { return m.allFinite(); }

// The implicit matrix and its factor in node-block panels (MassSpring's envelope): panel J is column block J, rows
// J..last(J) in 3 (last(J) - J + 1) scalar rows, its 3 columns one after the other. Block (I, J), I >= J, starts at
// panel J's offset + 3 (I - J) with column stride rows(J).
struct Panels {
  const MassSpring& sys;
  double* a;
  int rows(int j) const { return 3 * (sys.last_slot(j) - j + 1); }
  double* panel(int j) const { return a + sys.panel_offset(j); }
  // Adds the symmetric 3x3 block m at slots (si, sj), both >= 0; on the diagonal only the lower triangle.
  void add(int si, int sj, const Eigen::Matrix3d& m) const {
    if (si < sj) std::swap(si, sj);
    const int h = rows(sj);
    double* b = panel(sj) + 3 * (si - sj);
    if (si == sj) {
      b[0] += m(0, 0);
      b[1] += m(1, 0);
      b[2] += m(2, 0);
      b[h + 1] += m(1, 1);
      b[h + 2] += m(2, 1);
      b[2 * h + 2] += m(2, 2);
      return;
    }
    for (int c = 0; c < 3; ++c) {
      for (int r = 0; r < 3; ++r) b[c * h + r] += m(r, c);
    }
  }
  // Adds s (alpha u u^T + beta I) at (si, si) and (sj, sj) and subtracts it at (si, sj): a spring's block pattern.
  // Fixed nodes (slot -1) are skipped.
  void add_spring(int si, int sj, const Eigen::Vector3d& u, double alpha, double beta) const {
    const double xx = alpha * u.x() * u.x() + beta, yy = alpha * u.y() * u.y() + beta,
                 zz = alpha * u.z() * u.z() + beta, xy = alpha * u.x() * u.y(), xz = alpha * u.x() * u.z(),
                 yz = alpha * u.y() * u.z();
    for (const int s : {si, sj}) {
      if (s < 0) continue;
      const int h = rows(s);
      double* b = panel(s);
      b[0] += xx;
      b[1] += xy;
      b[2] += xz;
      b[h + 1] += yy;
      b[h + 2] += yz;
      b[2 * h + 2] += zz;
    }
    if (si < 0 || sj < 0) return;
    const int lo = std::min(si, sj), hi = std::max(si, sj);
    const int h = rows(lo);
    double* b = panel(lo) + 3 * (hi - lo);
    double* b1 = b + h;
    double* b2 = b1 + h;
    b[0] -= xx;
    b[1] -= xy;
    b[2] -= xz;
    b1[0] -= xy;
    b1[1] -= yy;
    b1[2] -= yz;
    b2[0] -= xz;
    b2[1] -= yz;
    b2[2] -= zz;
  }

  // In-place Cholesky A = L L^T by node blocks, left-looking, with the forward substitution L y = b fused in
  // (b in slot order becomes y). Returns the smallest scalar pivot (<= 0 or NaN: not positive definite, stopped
  // there); the largest is left in max_pivot. The diagonal blocks keep garbage above their diagonal (never read).
  double factor(double* b, double& max_pivot) const {
    const int nodes = sys.free_count();
    double min_pivot = 1e300;
    max_pivot = 0;
    for (int j = 0; j < nodes; ++j) {
      const int h = rows(j);
      double* p0 = panel(j);
      double* p1 = p0 + h;
      double* p2 = p1 + h;
      // P(J.., :) -= L(J.., K) L(J, K)^T for every column block K with L(J, K) != 0 (rows J..last(K)).
      for (int k = sys.first_slot(j); k < j; ++k) {
        const int hk = rows(k), off = 3 * (j - k), len = hk - off;
        const double* l0 = panel(k) + off;
        const double* l1 = l0 + hk;
        const double* l2 = l1 + hk;
        const double w00 = l0[0], w01 = l1[0], w02 = l2[0];  // L(J + c, K + m) = w_cm
        const double w10 = l0[1], w11 = l1[1], w12 = l2[1];
        const double w20 = l0[2], w21 = l1[2], w22 = l2[2];
        for (int t = 0; t < len; ++t) {
          const double a0 = l0[t], a1 = l1[t], a2 = l2[t];
          p0[t] -= (a0 * w00 + a1 * w01) + a2 * w02;
          p1[t] -= (a0 * w10 + a1 * w11) + a2 * w12;
          p2[t] -= (a0 * w20 + a1 * w21) + a2 * w22;
        }
      }
      // The diagonal block: 3 x 3 Cholesky.
      const double d0 = p0[0];
      if (!(d0 > 0) || !std::isfinite(d0)) return d0 > 0 ? -1 : d0;
      const double l00 = std::sqrt(d0), i0 = 1.0 / l00;
      const double l10 = p0[1] * i0, l20 = p0[2] * i0;
      const double d1 = p1[1] - l10 * l10;
      if (!(d1 > 0) || !std::isfinite(d1)) return d1 > 0 ? -1 : d1;
      const double l11 = std::sqrt(d1), i1 = 1.0 / l11;
      const double l21 = (p1[2] - l20 * l10) * i1;
      const double d2 = p2[2] - l20 * l20 - l21 * l21;
      if (!(d2 > 0) || !std::isfinite(d2)) return d2 > 0 ? -1 : d2;
      const double l22 = std::sqrt(d2), i2 = 1.0 / l22;
      p0[0] = i0;  // the diagonal holds the reciprocal pivots: the solves multiply
      p0[1] = l10;
      p0[2] = l20;
      p1[1] = i1;
      p1[2] = l21;
      p2[2] = i2;
      min_pivot = std::min(min_pivot, std::min(l00, std::min(l11, l22)));
      max_pivot = std::max(max_pivot, std::max(l00, std::max(l11, l22)));
      // The rows below: L(I, J) = P(I, J) L(J, J)^-T.
      for (int t = 3; t < h; ++t) {
        const double x0 = p0[t] * i0;
        const double x1 = (p1[t] - x0 * l10) * i1;
        const double x2 = (p2[t] - x0 * l20 - x1 * l21) * i2;
        p0[t] = x0;
        p1[t] = x1;
        p2[t] = x2;
      }
      // Forward substitution of this block, and its contribution to the rows below.
      double* bj = b + 3 * j;
      const double y0 = bj[0] * i0;
      const double y1 = (bj[1] - l10 * y0) * i1;
      const double y2 = (bj[2] - l20 * y0 - l21 * y1) * i2;
      bj[0] = y0;
      bj[1] = y1;
      bj[2] = y2;
      for (int t = 3; t < h; ++t) bj[t] -= (p0[t] * y0 + p1[t] * y1) + p2[t] * y2;
    }
    return min_pivot;
  }

  // After factor(): solves L^T x = y in place.
  void solve_back(double* b) const {
    for (int j = sys.free_count() - 1; j >= 0; --j) {
      const int h = rows(j);
      const double* p0 = panel(j);
      const double* p1 = p0 + h;
      const double* p2 = p1 + h;
      double* bj = b + 3 * j;
      double z0 = bj[0], z1 = bj[1], z2 = bj[2];
      for (int t = 3; t < h; ++t) {
        z0 -= p0[t] * bj[t];
        z1 -= p1[t] * bj[t];
        z2 -= p2[t] * bj[t];
      }
      const double x2 = z2 * p2[2];
      const double x1 = (z1 - p1[2] * x2) * p1[1];
      const double x0 = (z0 - p0[1] * x1 - p0[2] * x2) * p0[0];
      bj[0] = x0;
      bj[1] = x1;
      bj[2] = x2;
    }
  }
};

// Forces (N) on every node at (x, v) (the explicit step).
void forces(const MassSpring& sys, const PenaltyContact* contacts, int count, const Eigen::Matrix3Xd& x,
            const Eigen::Matrix3Xd& v, Eigen::Matrix3Xd& f) {
  const int n = sys.node_count();
  const auto& mass = sys.mass();
  for (int i = 0; i < n; ++i) f.col(i) = mass[static_cast<std::size_t>(i)] * (sys.gravity() - sys.drag() * v.col(i));
  for (const Spring& sp : sys.springs()) {
    const Eigen::Vector3d d = x.col(sp.j) - x.col(sp.i);
    const double l = d.norm();
    if (!(l > 1e-12)) continue;
    const Eigen::Vector3d u = d / l;
    const Eigen::Vector3d fi = (sp.stiffness * (l - sp.rest) + sp.damping * (v.col(sp.j) - v.col(sp.i)).dot(u)) * u;
    f.col(sp.i) += fi;
    f.col(sp.j) -= fi;
  }
  for (int c = 0; c < count; ++c) {
    const PenaltyContact& pc = contacts[c];
    const double mag = pc.stiffness * pc.depth;
    for (int k = 0; k < pc.count; ++k) {
      f.col(pc.nodes[static_cast<std::size_t>(k)]) += pc.weights[static_cast<std::size_t>(k)] * mag * pc.normal;
    }
  }
}

// The implicit step's system: g = f + h K v on every node (f the forces at (x, v)), and the matrix M - h D - h^2 K
// assembled into the panels (zeroed before). Springs of (near) zero length have no direction and are skipped this
// step.
void assemble(const MassSpring& sys, const PenaltyContact* contacts, int count, const Eigen::Matrix3Xd& x,
              const Eigen::Matrix3Xd& v, double h, Eigen::Matrix3Xd& g, const Panels& m) {
  const int n = sys.node_count();
  const auto& mass = sys.mass();
  const double h2 = h * h;
  for (int i = 0; i < n; ++i) {
    const double mi = mass[static_cast<std::size_t>(i)];
    g.col(i) = mi * (sys.gravity() - sys.drag() * v.col(i));
    const int s = sys.slot(i);
    if (s < 0) continue;
    const double d = mi * (1.0 + h * sys.drag());
    const int rows = m.rows(s);
    double* b = m.panel(s);
    b[0] += d;
    b[rows + 1] += d;
    b[2 * rows + 2] += d;
  }
  for (const Spring& sp : sys.springs()) {
    const Eigen::Vector3d d = x.col(sp.j) - x.col(sp.i);
    const double l = d.norm();
    if (!(l > 1e-12)) continue;
    const double inv_l = 1.0 / l;
    const Eigen::Vector3d u = d * inv_l;
    const Eigen::Vector3d dv = v.col(sp.j) - v.col(sp.i);
    const double udv = u.dot(dv);
    // Ks = k ((1 - t) u u^T + t I), t = max(0, 1 - rest / l): df_i/dx_i = -Ks (positive semi-definite by the clamp).
    const double t = std::max(0.0, 1.0 - sp.rest * inv_l);
    const double kt = sp.stiffness * t;
    // f_i + h (K v)_i, with (K v)_i = Ks (v_j - v_i).
    const Eigen::Vector3d gi = (sp.stiffness * (l - sp.rest) + sp.damping * udv + h * (sp.stiffness - kt) * udv) * u +
                               (h * kt) * dv;
    g.col(sp.i) += gi;
    g.col(sp.j) -= gi;
    // h^2 Ks + h c u u^T = alpha u u^T + beta I.
    m.add_spring(sys.slot(sp.i), sys.slot(sp.j), u, h2 * (sp.stiffness - kt) + h * sp.damping, h2 * kt);
  }
  for (int c = 0; c < count; ++c) {
    const PenaltyContact& pc = contacts[c];
    const double mag = pc.stiffness * pc.depth;
    Eigen::Vector3d pv = Eigen::Vector3d::Zero();
    for (int k = 0; k < pc.count; ++k) pv += pc.weights[static_cast<std::size_t>(k)] * v.col(pc.nodes[static_cast<std::size_t>(k)]);
    // df_a/dx_b = -k w_a w_b n n^T; couplings outside the envelope are dropped (the diagonal blocks stay).
    const Eigen::Matrix3d nn = pc.normal * pc.normal.transpose();
    const double npv = pc.normal.dot(pv);
    for (int a = 0; a < pc.count; ++a) {
      const int na = pc.nodes[static_cast<std::size_t>(a)];
      const double wa = pc.weights[static_cast<std::size_t>(a)];
      g.col(na) += (wa * mag - h * pc.stiffness * wa * npv) * pc.normal;
      const int sa = sys.slot(na);
      if (sa < 0) continue;
      for (int b = 0; b < pc.count; ++b) {
        const int sb = sys.slot(pc.nodes[static_cast<std::size_t>(b)]);
        if (sb < 0 || sb > sa || sb < sys.first_slot(sa)) continue;
        m.add(sa, sb, (h2 * pc.stiffness * wa * pc.weights[static_cast<std::size_t>(b)]) * nn);
      }
    }
  }
}

}  // namespace

IntegrateStatus integrate(const MassSpring& sys, Integrator integrator, const PenaltyContact* contacts, int count,
                          double dt, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, MassSpringWorkspace& w) noexcept {
  const int n = sys.node_count();
  w.x0_ = x;
  w.v0_ = v;
  auto restore = [&](IntegrateStatus s) {
    x = w.x0_;
    v = w.v0_;
    return s;
  };
  if (!(dt > 0) || !std::isfinite(dt)) return IntegrateStatus::kNonFinite;
  const auto& inv_mass = sys.inverse_mass();

  if (integrator == Integrator::kSymplecticEuler) {
    forces(sys, contacts, count, x, v, w.force_);
    for (int i = 0; i < n; ++i) {
      if (sys.fixed(i)) {
        v.col(i).setZero();
        continue;
      }
      v.col(i) += (dt * inv_mass[static_cast<std::size_t>(i)]) * w.force_.col(i);
      x.col(i) += dt * v.col(i);
    }
  } else {
    std::fill(w.factor_.begin(), w.factor_.end(), 0.0);
    const Panels panels{sys, w.factor_.data()};
    assemble(sys, contacts, count, x, v, dt, w.force_, panels);
    if (!finite(w.force_)) return restore(IntegrateStatus::kNonFinite);
    // rhs = h (f + h K v), in slot order.
    for (int s = 0; s < sys.free_count(); ++s) {
      const int node = sys.node_of_slot(s);
      for (int c = 0; c < 3; ++c) w.rhs_[static_cast<std::size_t>(3 * s + c)] = dt * w.force_(c, node);
    }
    w.min_pivot_ = panels.factor(w.rhs_.data(), w.max_pivot_);
    if (!(w.min_pivot_ > 0)) return restore(IntegrateStatus::kNotPositive);
    panels.solve_back(w.rhs_.data());
    for (int s = 0; s < sys.free_count(); ++s) {
      const int node = sys.node_of_slot(s);
      for (int c = 0; c < 3; ++c) v(c, node) += w.rhs_[static_cast<std::size_t>(3 * s + c)];
      x.col(node) += dt * v.col(node);
    }
    for (int i = 0; i < n; ++i) {
      if (sys.fixed(i)) v.col(i).setZero();
    }
  }
  if (!finite(x) || !finite(v)) return restore(IntegrateStatus::kNonFinite);
  return IntegrateStatus::kOk;
}

}  // namespace surgsim::intestine
