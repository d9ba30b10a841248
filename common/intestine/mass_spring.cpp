#include "intestine/mass_spring.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "core/error.h"

using namespace surgsim::core;

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
  if (factor_size() > static_cast<std::size_t>(std::numeric_limits<int>::max())) {
    throw_error("mass-spring: the factor's envelope is too large (", factor_size(), " entries)");
  }
  // Each spring's blocks: block (a, b), a >= b, at panel b's offset + 3 (a - b), column stride 3 (last(b) - b + 1).
  auto block = [&](int a, int b, int& offset, int& stride) {
    const auto ub = static_cast<std::size_t>(b);
    offset = static_cast<int>(panel_offset_[ub]) + 3 * (a - b);
    stride = 3 * (last_slot_[ub] - b + 1);
  };
  spring_blocks_.resize(springs_.size());
  for (std::size_t k = 0; k < springs_.size(); ++k) {
    SpringBlocks& sb = spring_blocks_[k];
    sb.spring = static_cast<int>(k);
    const int a = slot_[static_cast<std::size_t>(springs_[k].i)], b = slot_[static_cast<std::size_t>(springs_[k].j)];
    if (a >= 0) block(a, a, sb.diag_i, sb.stride_i);
    if (b >= 0) block(b, b, sb.diag_j, sb.stride_j);
    if (a >= 0 && b >= 0) block(std::max(a, b), std::min(a, b), sb.off, sb.stride);
  }
  auto low = [&](const SpringBlocks& sb) {
    const int a = slot_[static_cast<std::size_t>(springs_[static_cast<std::size_t>(sb.spring)].i)],
              b = slot_[static_cast<std::size_t>(springs_[static_cast<std::size_t>(sb.spring)].j)];
    return a < 0 ? b : b < 0 ? a : std::min(a, b);
  };
  std::stable_sort(spring_blocks_.begin(), spring_blocks_.end(),
                   [&](const SpringBlocks& x, const SpringBlocks& y) { return low(x) < low(y); });
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
  // Adds alpha u u^T + beta I at a spring's two diagonal blocks and subtracts it at its off-diagonal one.
  void add_spring(const SpringBlocks& sb, const double* u, double alpha, double beta) const {
    const double xx = alpha * u[0] * u[0] + beta, yy = alpha * u[1] * u[1] + beta, zz = alpha * u[2] * u[2] + beta,
                 xy = alpha * u[0] * u[1], xz = alpha * u[0] * u[2], yz = alpha * u[1] * u[2];
    auto diagonal = [&](int offset, int h) {
      double* b = a + offset;
      b[0] += xx;
      b[1] += xy;
      b[2] += xz;
      b[h + 1] += yy;
      b[h + 2] += yz;
      b[2 * h + 2] += zz;
    };
    if (sb.diag_i >= 0) diagonal(sb.diag_i, sb.stride_i);
    if (sb.diag_j >= 0) diagonal(sb.diag_j, sb.stride_j);
    if (sb.off < 0) return;
    double* b = a + sb.off;
    double* b1 = b + sb.stride;
    double* b2 = b1 + sb.stride;
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

  // Column block K of L seen from row block J: rows J..last(K) (len scalars from l0, l1, l2) and the block L(J, K).
  struct Source {
    const double *l0, *l1, *l2;
    int len;
    double w[9];  // w[3 c + m] = L(J + c, K + m)
    Source(const Panels& m, int k, int j) {
      const int hk = m.rows(k), off = 3 * (j - k);
      len = hk - off;
      l0 = m.panel(k) + off;
      l1 = l0 + hk;
      l2 = l1 + hk;
      for (int c = 0; c < 3; ++c) {
        w[3 * c] = l0[c];
        w[3 * c + 1] = l1[c];
        w[3 * c + 2] = l2[c];
      }
    }
  };
  // P(from..to, :) -= L(.., K) L(J, K)^T for one source block, and for two at once (one pass over P).
  static void update(double* __restrict p0, double* __restrict p1, double* __restrict p2,
                     const double* __restrict a0, const double* __restrict a1, const double* __restrict a2,
                     const double* w, int from, int to) {
    const double w00 = w[0], w01 = w[1], w02 = w[2], w10 = w[3], w11 = w[4], w12 = w[5], w20 = w[6], w21 = w[7],
                 w22 = w[8];
    for (int t = from; t < to; ++t) {
      p0[t] -= (a0[t] * w00 + a1[t] * w01) + a2[t] * w02;
      p1[t] -= (a0[t] * w10 + a1[t] * w11) + a2[t] * w12;
      p2[t] -= (a0[t] * w20 + a1[t] * w21) + a2[t] * w22;
    }
  }
  static void update2(double* __restrict p0, double* __restrict p1, double* __restrict p2,
                      const double* __restrict a0, const double* __restrict a1, const double* __restrict a2,
                      const double* __restrict b0, const double* __restrict b1, const double* __restrict b2,
                      const double* wa, const double* wb, int len) {
    const double a00 = wa[0], a01 = wa[1], a02 = wa[2], a10 = wa[3], a11 = wa[4], a12 = wa[5], a20 = wa[6],
                 a21 = wa[7], a22 = wa[8];
    const double b00 = wb[0], b01 = wb[1], b02 = wb[2], b10 = wb[3], b11 = wb[4], b12 = wb[5], b20 = wb[6],
                 b21 = wb[7], b22 = wb[8];
    for (int t = 0; t < len; ++t) {
      p0[t] -= ((a0[t] * a00 + a1[t] * a01) + a2[t] * a02) + ((b0[t] * b00 + b1[t] * b01) + b2[t] * b02);
      p1[t] -= ((a0[t] * a10 + a1[t] * a11) + a2[t] * a12) + ((b0[t] * b10 + b1[t] * b11) + b2[t] * b12);
      p2[t] -= ((a0[t] * a20 + a1[t] * a21) + a2[t] * a22) + ((b0[t] * b20 + b1[t] * b21) + b2[t] * b22);
    }
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
      // P(J.., :) -= L(J.., K) L(J, K)^T for every column block K with L(J, K) != 0 (rows J..last(K)), two blocks
      // K at a time (one pass over P for both); a later K reaches as far down as an earlier one or further.
      int k = sys.first_slot(j);
      for (; k + 1 < j; k += 2) {
        const Source a(*this, k, j), b(*this, k + 1, j);
        update2(p0, p1, p2, a.l0, a.l1, a.l2, b.l0, b.l1, b.l2, a.w, b.w, a.len);
        update(p0, p1, p2, b.l0, b.l1, b.l2, b.w, a.len, b.len);
      }
      if (k < j) {
        const Source a(*this, k, j);
        update(p0, p1, p2, a.l0, a.l1, a.l2, a.w, 0, a.len);
      }
      // The diagonal block: 3 x 3 Cholesky, in the order that keeps the chain of divisions and square roots short
      // (the pivots d are those of L D L^T; L's diagonal is sqrt(d), its reciprocal sqrt(1 / d)).
      const double d0 = p0[0];
      if (!(d0 > 0) || !std::isfinite(d0)) return d0 > 0 ? -1 : d0;
      const double r0 = 1.0 / d0, i0 = std::sqrt(r0);
      const double d1 = p1[1] - p0[1] * p0[1] * r0;
      if (!(d1 > 0) || !std::isfinite(d1)) return d1 > 0 ? -1 : d1;
      const double r1 = 1.0 / d1, i1 = std::sqrt(r1);
      const double m21 = p1[2] - p0[2] * p0[1] * r0;
      const double d2 = p2[2] - p0[2] * p0[2] * r0 - m21 * m21 * r1;
      if (!(d2 > 0) || !std::isfinite(d2)) return d2 > 0 ? -1 : d2;
      const double i2 = std::sqrt(1.0 / d2);
      const double l10 = p0[1] * i0, l20 = p0[2] * i0, l21 = m21 * i1;
      const double l00 = d0 * i0, l11 = d1 * i1, l22 = d2 * i2;
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
      // z = y_J - L(J+1.., J)^T x(J+1..), from the last row up: the rows of block J + 1, solved just before, come
      // last, so little of the sum waits for them.
      double z0 = 0, z1 = 0, z2 = 0;
      for (int t = h - 1; t >= 3; --t) {
        z0 += p0[t] * bj[t];
        z1 += p1[t] * bj[t];
        z2 += p2[t] * bj[t];
      }
      z0 = bj[0] - z0;
      z1 = bj[1] - z1;
      z2 = bj[2] - z2;
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
  // The springs in chunks, two passes each: first every spring's direction and coefficients (independent of each
  // other, so the square roots and divisions of several springs overlap), then their sums into g and the matrix.
  const Spring* springs = sys.springs().data();
  const SpringBlocks* blocks = sys.spring_blocks().data();
  const int spring_count = static_cast<int>(sys.spring_blocks().size());
  const double* px = x.data();
  const double* pv = v.data();
  double* pg = g.data();
  constexpr int kChunk = 32;
  struct Term {
    double u[3], e[3];   // direction, v_j - v_i
    double a, b;         // f_i + h (K v)_i = a u + b (v_j - v_i)
    double alpha, beta;  // h^2 Ks + h c u u^T = alpha u u^T + beta I
    bool skip;           // (near) zero length
  };
  Term terms[kChunk];
  for (int start = 0; start < spring_count; start += kChunk) {
    const int end = std::min(spring_count, start + kChunk);
    for (int k = start; k < end; ++k) {
      const Spring& sp = springs[blocks[k].spring];
      Term& tm = terms[k - start];
      const double* xi = px + 3 * sp.i;
      const double* xj = px + 3 * sp.j;
      const double d0 = xj[0] - xi[0], d1 = xj[1] - xi[1], d2 = xj[2] - xi[2];
      const double l = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2);
      tm.skip = !(l > 1e-12);
      const double inv_l = 1.0 / l;
      tm.u[0] = d0 * inv_l;
      tm.u[1] = d1 * inv_l;
      tm.u[2] = d2 * inv_l;
      const double* vi = pv + 3 * sp.i;
      const double* vj = pv + 3 * sp.j;
      tm.e[0] = vj[0] - vi[0];
      tm.e[1] = vj[1] - vi[1];
      tm.e[2] = vj[2] - vi[2];
      const double udv = tm.u[0] * tm.e[0] + tm.u[1] * tm.e[1] + tm.u[2] * tm.e[2];
      // Ks = k ((1 - t) u u^T + t I), t = max(0, 1 - rest / l): df_i/dx_i = -Ks (positive semi-definite by the
      // clamp); (K v)_i = Ks (v_j - v_i).
      const double kt = sp.stiffness * std::max(0.0, 1.0 - sp.rest * inv_l);
      tm.a = sp.stiffness * (l - sp.rest) + sp.damping * udv + h * (sp.stiffness - kt) * udv;
      tm.b = h * kt;
      tm.alpha = h2 * (sp.stiffness - kt) + h * sp.damping;
      tm.beta = h2 * kt;
    }
    for (int k = start; k < end; ++k) {
      const Term& tm = terms[k - start];
      if (tm.skip) continue;
      const Spring& sp = springs[blocks[k].spring];
      const double g0 = tm.a * tm.u[0] + tm.b * tm.e[0], g1 = tm.a * tm.u[1] + tm.b * tm.e[1],
                   g2 = tm.a * tm.u[2] + tm.b * tm.e[2];
      double* gi = pg + 3 * sp.i;
      double* gj = pg + 3 * sp.j;
      gi[0] += g0;
      gi[1] += g1;
      gi[2] += g2;
      gj[0] -= g0;
      gj[1] -= g1;
      gj[2] -= g2;
      m.add_spring(blocks[k], tm.u, tm.alpha, tm.beta);
    }
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
  if (!(dt > 0) || !std::isfinite(dt)) return IntegrateStatus::kNonFinite;
  const auto& inv_mass = sys.inverse_mass();

  if (integrator == Integrator::kSymplecticEuler) {
    w.x0_ = x;
    w.v0_ = v;
    forces(sys, contacts, count, x, v, w.force_);
    for (int i = 0; i < n; ++i) {
      if (sys.fixed(i)) {
        v.col(i).setZero();
        continue;
      }
      v.col(i) += (dt * inv_mass[static_cast<std::size_t>(i)]) * w.force_.col(i);
      x.col(i) += dt * v.col(i);
    }
    if (!finite(x) || !finite(v)) {
      x = w.x0_;
      v = w.v0_;
      return IntegrateStatus::kNonFinite;
    }
    return IntegrateStatus::kOk;
  }
  // Implicit: x and v are written only once the new values are known to be finite (nothing to restore).
  std::fill(w.factor_.begin(), w.factor_.end(), 0.0);
  const Panels panels{sys, w.factor_.data()};
  assemble(sys, contacts, count, x, v, dt, w.force_, panels);
  if (!finite(w.force_)) return IntegrateStatus::kNonFinite;
  // rhs = h (f + h K v), in slot order.
  const int free = sys.free_count();
  double* rhs = w.rhs_.data();
  for (int s = 0; s < free; ++s) {
    const double* g = w.force_.col(sys.node_of_slot(s)).data();
    rhs[3 * s] = dt * g[0];
    rhs[3 * s + 1] = dt * g[1];
    rhs[3 * s + 2] = dt * g[2];
  }
  w.min_pivot_ = panels.factor(rhs, w.max_pivot_);
  if (!(w.min_pivot_ > 0)) return IntegrateStatus::kNotPositive;
  panels.solve_back(rhs);
  // v += dv, x += h v: checked first, then written.
  bool ok = true;
  for (int s = 0; s < free; ++s) {
    const int node = sys.node_of_slot(s);
    for (int c = 0; c < 3; ++c) {
      const double vn = v(c, node) + rhs[3 * s + c];
      ok = ok && std::isfinite(vn) && std::isfinite(x(c, node) + dt * vn);
    }
  }
  for (int i = 0; i < n; ++i) {
    if (sys.fixed(i)) ok = ok && x.col(i).allFinite();
  }
  if (!ok) return IntegrateStatus::kNonFinite;
  for (int s = 0; s < free; ++s) {
    const int node = sys.node_of_slot(s);
    for (int c = 0; c < 3; ++c) {
      v(c, node) += rhs[3 * s + c];
      x(c, node) += dt * v(c, node);
    }
  }
  for (int i = 0; i < n; ++i) {
    if (sys.fixed(i)) v.col(i).setZero();
  }
  return IntegrateStatus::kOk;
}

}  // namespace surgsim::intestine
