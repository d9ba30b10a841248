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
  n_ = 3 * system.free_count();
  p_ = system.scalar_band();
  band_.assign(static_cast<std::size_t>(n_) * static_cast<std::size_t>(p_ + 1), 0.0);
  rhs_.assign(static_cast<std::size_t>(n_), 0.0);
  force_.setZero(3, system.node_count());
  kv_.setZero(3, system.node_count());
  x0_.setZero(3, system.node_count());
  v0_.setZero(3, system.node_count());
}

namespace {

bool finite(const Eigen::Matrix3Xd& m) { return m.allFinite(); }

// a . b over n entries with four independent accumulators: the factorization's inner loop would otherwise wait on
// the latency of one chain of multiply-adds.
inline double dot(const double* a, const double* b, int n) {
  double s0 = 0, s1 = 0, s2 = 0, s3 = 0;
  int k = 0;
  for (; k + 4 <= n; k += 4) {
    s0 += a[k] * b[k];
    s1 += a[k + 1] * b[k + 1];
    s2 += a[k + 2] * b[k + 2];
    s3 += a[k + 3] * b[k + 3];
  }
  for (; k < n; ++k) s0 += a[k] * b[k];
  return (s0 + s1) + (s2 + s3);
}

// Lower band of a symmetric matrix, column-major: column c holds rows c..c+p contiguously, entry (r, c) at
// band[c (p + 1) + r - c]. Column storage makes the factorization's updates independent axpys (no serial chain of
// divisions as in a row-by-row Cholesky).
struct Band {
  double* a;
  int n, p;
  double max_pivot = 0;  // largest pivot of the last factor()
  double* col(int c) { return a + static_cast<std::size_t>(c) * static_cast<std::size_t>(p + 1); }
  double& at(int r, int c) { return col(c)[r - c]; }

  // Adds the 3x3 block m at node slots (si, sj); only the lower triangle is stored.
  void add(int si, int sj, const Eigen::Matrix3d& m) {
    if (si < sj) {
      add(sj, si, m.transpose());
      return;
    }
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        const int R = 3 * si + r, C = 3 * sj + c;
        if (C <= R && R - C <= p) at(R, C) += m(r, c);
      }
    }
  }

  // In-place Cholesky A = L L^T, left-looking by columns. Returns the smallest pivot (<= 0: not positive definite);
  // the largest is left in max_pivot.
  double factor() {
    double min_pivot = 1e300;
    max_pivot = 0;
    for (int j = 0; j < n; ++j) {
      double* cj = col(j);
      const int rows = std::min(p, n - 1 - j) + 1;  // rows j .. j + rows - 1
      // cj -= sum_k L(j, k) L(j.., k), four columns k at a time (column k reaches row k + p, so each later column
      // is one entry longer: the common part first, then the tails).
      int k = std::max(0, j - p);
      for (; k + 3 < j; k += 4) {
        const double* c0 = col(k) + (j - k);
        const double* c1 = col(k + 1) + (j - k - 1);
        const double* c2 = col(k + 2) + (j - k - 2);
        const double* c3 = col(k + 3) + (j - k - 3);
        const double f0 = c0[0], f1 = c1[0], f2 = c2[0], f3 = c3[0];
        const int l0 = std::min(rows, k + p - j + 1), l1 = std::min(rows, l0 + 1), l2 = std::min(rows, l0 + 2),
                  l3 = std::min(rows, l0 + 3);
        for (int t = 0; t < l0; ++t) cj[t] -= (f0 * c0[t] + f1 * c1[t]) + (f2 * c2[t] + f3 * c3[t]);
        for (int t = l0; t < l1; ++t) cj[t] -= f1 * c1[t] + (f2 * c2[t] + f3 * c3[t]);
        for (int t = l1; t < l2; ++t) cj[t] -= f2 * c2[t] + f3 * c3[t];
        for (int t = l2; t < l3; ++t) cj[t] -= f3 * c3[t];
      }
      for (; k < j; ++k) {
        const double* ck = col(k) + (j - k);  // L(j.., k)
        const double f = ck[0];
        const int len = std::min(rows, k + p - j + 1);
        for (int t = 0; t < len; ++t) cj[t] -= f * ck[t];
      }
      const double d = cj[0];
      if (!(d > 0) || !std::isfinite(d)) return d > 0 ? -1 : d;
      const double l = std::sqrt(d), inv = 1.0 / l;
      cj[0] = l;
      for (int t = 1; t < rows; ++t) cj[t] *= inv;
      min_pivot = std::min(min_pivot, l);
      max_pivot = std::max(max_pivot, l);
    }
    return min_pivot;
  }

  // Solves L L^T x = b in place.
  void solve(double* b) {
    for (int j = 0; j < n; ++j) {
      const double* cj = col(j);
      const int rows = std::min(p, n - 1 - j) + 1;
      const double y = b[j] / cj[0];
      b[j] = y;
      for (int t = 1; t < rows; ++t) b[j + t] -= cj[t] * y;
    }
    for (int j = n - 1; j >= 0; --j) {
      const double* cj = col(j);
      const int rows = std::min(p, n - 1 - j) + 1;
      b[j] = (b[j] - dot(cj + 1, b + j + 1, rows - 1)) / cj[0];
    }
  }
};

// Forces (N) on every node at (x, v); with `implicit`, also assembles the matrix M - h D - h^2 K into `band` and
// K v into `kv`. Springs of (near) zero length have no direction and are skipped this step.
void forces(const MassSpring& sys, const PenaltyContact* contacts, int count, const Eigen::Matrix3Xd& x,
            const Eigen::Matrix3Xd& v, double h, Eigen::Matrix3Xd& f, Band* band, Eigen::Matrix3Xd* kv) {
  const int n = sys.node_count();
  const auto& mass = sys.mass();
  for (int i = 0; i < n; ++i) {
    const double m = mass[static_cast<std::size_t>(i)];
    f.col(i) = m * (sys.gravity() - sys.drag() * v.col(i));
  }
  if (band) {
    kv->setZero();
    for (int i = 0; i < n; ++i) {
      const int s = sys.slot(i);
      if (s < 0) continue;
      const double d = mass[static_cast<std::size_t>(i)] * (1.0 + h * sys.drag());
      for (int c = 0; c < 3; ++c) band->at(3 * s + c, 3 * s + c) += d;
    }
  }
  const double h2 = h * h;
  for (const Spring& sp : sys.springs()) {
    const Eigen::Vector3d d = x.col(sp.j) - x.col(sp.i);
    const double l = d.norm();
    if (!(l > 1e-12)) continue;
    const Eigen::Vector3d u = d / l;
    const Eigen::Vector3d dv = v.col(sp.j) - v.col(sp.i);
    const Eigen::Vector3d fi = (sp.stiffness * (l - sp.rest) + sp.damping * dv.dot(u)) * u;
    f.col(sp.i) += fi;
    f.col(sp.j) -= fi;
    if (!band) continue;
    // Ks = k (u u^T + max(0, 1 - rest / l) (I - u u^T)): df_i/dx_i = -Ks (positive semi-definite by the clamp).
    const Eigen::Matrix3d uu = u * u.transpose();
    const double t = std::max(0.0, 1.0 - sp.rest / l);
    const Eigen::Matrix3d ks = sp.stiffness * ((1.0 - t) * uu + t * Eigen::Matrix3d::Identity());
    const Eigen::Vector3d kvi = -ks * (-dv);  // (K v)_i = -Ks (v_i - v_j)
    kv->col(sp.i) += kvi;
    kv->col(sp.j) -= kvi;
    const Eigen::Matrix3d a = h2 * ks + (h * sp.damping) * uu;
    const int si = sys.slot(sp.i), sj = sys.slot(sp.j);
    if (si >= 0) band->add(si, si, a);
    if (sj >= 0) band->add(sj, sj, a);
    if (si >= 0 && sj >= 0) band->add(si, sj, -a);
  }
  for (int c = 0; c < count; ++c) {
    const PenaltyContact& pc = contacts[c];
    const double mag = pc.stiffness * pc.depth;
    Eigen::Vector3d pv = Eigen::Vector3d::Zero();
    for (int k = 0; k < pc.count; ++k) {
      f.col(pc.nodes[static_cast<std::size_t>(k)]) += pc.weights[static_cast<std::size_t>(k)] * mag * pc.normal;
      pv += pc.weights[static_cast<std::size_t>(k)] * v.col(pc.nodes[static_cast<std::size_t>(k)]);
    }
    if (!band) continue;
    // df_a/dx_b = -k w_a w_b n n^T; couplings outside the band are dropped (the diagonal blocks stay).
    const Eigen::Matrix3d nn = pc.normal * pc.normal.transpose();
    const double npv = pc.normal.dot(pv);
    for (int a = 0; a < pc.count; ++a) {
      const int na = pc.nodes[static_cast<std::size_t>(a)];
      const double wa = pc.weights[static_cast<std::size_t>(a)];
      kv->col(na) -= pc.stiffness * wa * npv * pc.normal;
      const int sa = sys.slot(na);
      if (sa < 0) continue;
      for (int b = 0; b < pc.count; ++b) {
        const int sb = sys.slot(pc.nodes[static_cast<std::size_t>(b)]);
        if (sb < 0 || sb > sa || sa - sb > sys.node_band()) continue;
        const Eigen::Matrix3d blk = (h2 * pc.stiffness * wa * pc.weights[static_cast<std::size_t>(b)]) * nn;
        band->add(sa, sb, blk);
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
    forces(sys, contacts, count, x, v, dt, w.force_, nullptr, nullptr);
    for (int i = 0; i < n; ++i) {
      if (sys.fixed(i)) {
        v.col(i).setZero();
        continue;
      }
      v.col(i) += (dt * inv_mass[static_cast<std::size_t>(i)]) * w.force_.col(i);
      x.col(i) += dt * v.col(i);
    }
  } else {
    std::fill(w.band_.begin(), w.band_.end(), 0.0);
    Band band{w.band_.data(), w.n_, w.p_};
    forces(sys, contacts, count, x, v, dt, w.force_, &band, &w.kv_);
    if (!finite(w.force_) || !finite(w.kv_)) return restore(IntegrateStatus::kNonFinite);
    // rhs = h (f + h K v), in band order.
    for (int s = 0; s < sys.free_count(); ++s) {
      const int node = sys.node_of_slot(s);
      for (int c = 0; c < 3; ++c) {
        w.rhs_[static_cast<std::size_t>(3 * s + c)] = dt * (w.force_(c, node) + dt * w.kv_(c, node));
      }
    }
    w.min_pivot_ = band.factor();
    w.max_pivot_ = band.max_pivot;
    if (!(w.min_pivot_ > 0)) return restore(IntegrateStatus::kNotPositive);
    band.solve(w.rhs_.data());
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
