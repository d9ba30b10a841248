#include "compliance/patch_solve.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "fem/dense_llt.h"

using namespace surgsim::core;
using namespace surgsim::fem;

namespace surgsim::compliance {

PatchSolver::PatchSolver(const Tensors& tensors, const std::string& block_name)
    : tensors_(tensors), block_([&]() -> const TensorBlock& {
        const TensorBlock* b = tensors.find(block_name);
        if (!b) throw_error("patch solver: the tensors have no block '", block_name, "'");
        return *b;
      }()) {
  guu_.setZero(3 * kMaxContacts, 3 * kMaxContacts);
  wuu_.setZero(3 * kMaxContacts, 3 * kMaxContacts);
  a_.setZero(kMaxPatchRows, kMaxPatchRows);
  for (auto& m : m_) m.setZero();
  slot_node_.fill(-1);
  slot_of_node_.assign(tensors.column_of_node.size(), -1);
  slot_in_.setZero(3 * kMaxContacts);
  slot_out_.setZero(3 * kMaxContacts);
}

Eigen::Matrix3d PatchSolver::g(int a, int b) const noexcept { return blk(a, b); }

ContactStatus PatchSolver::prepare(const PatchConstraints& c, const Eigen::Matrix3d* rotations,
                                   RotationHalves halves) noexcept {
  prepared_nodes_ = 0;
  w_ = &guu_;
  const int n = c.node_count;
  if (n < 0 || n > kMaxContacts || c.patch_count < 0 || c.patch_count > kMaxPatches)
    return ContactStatus::kOverCapacity;
  for (int u = 0; u < n; ++u) {
    const ContactStatus st = contact_node_status(tensors_, block_, c.nodes[static_cast<std::size_t>(u)]);
    if (st != ContactStatus::kOk) return st;
  }
  const int entries = c.patch_start[static_cast<std::size_t>(c.patch_count)];
  if (entries < 0 || entries > kMaxPatchEntries) return ContactStatus::kOverCapacity;
  for (int e = 0; e < entries; ++e) {
    const double w = c.entry_weight[static_cast<std::size_t>(e)];
    const int u = c.entry_node[static_cast<std::size_t>(e)];
    if (!std::isfinite(w) || w < 0) return ContactStatus::kNonFinite;
    if (u < 0 || u >= n) return ContactStatus::kInvalidNode;
  }
  // Slots: the nodes of the last union keep theirs (and their blocks with one another); the others are freed and the
  // new nodes take them. A node listed twice shares its slot.
  ++stamp_;
  for (int u = 0; u < n; ++u) {
    const int s = slot_of_node_[static_cast<std::size_t>(c.nodes[static_cast<std::size_t>(u)])];
    slot_[static_cast<std::size_t>(u)] = s;
    fresh_[static_cast<std::size_t>(u)] = 0;
    if (s >= 0) slot_stamp_[static_cast<std::size_t>(s)] = stamp_;
  }
  for (int s = 0; s < kMaxContacts; ++s) {
    const int node = slot_node_[static_cast<std::size_t>(s)];
    if (node >= 0 && slot_stamp_[static_cast<std::size_t>(s)] != stamp_) {
      slot_of_node_[static_cast<std::size_t>(node)] = -1;
      slot_node_[static_cast<std::size_t>(s)] = -1;
    }
  }
  int free_slot = 0;
  for (int u = 0; u < n; ++u) {
    const int node = c.nodes[static_cast<std::size_t>(u)];
    int s = slot_of_node_[static_cast<std::size_t>(node)];
    if (s < 0) {  // n <= kMaxContacts distinct nodes: a free slot exists
      while (slot_node_[static_cast<std::size_t>(free_slot)] >= 0) ++free_slot;
      s = free_slot;
      slot_node_[static_cast<std::size_t>(s)] = node;
      slot_of_node_[static_cast<std::size_t>(node)] = s;
      slot_stamp_[static_cast<std::size_t>(s)] = stamp_;
      fresh_[static_cast<std::size_t>(u)] = 1;
    }
    slot_[static_cast<std::size_t>(u)] = s;
  }
  slot_end_ = 0;
  for (int u = 0; u < n; ++u) slot_end_ = std::max(slot_end_, slot_[static_cast<std::size_t>(u)] + 1);
  // G of the new slots against the union, symmetrized from both stored halves (as Superposition::solve; a symmetric
  // block stores one half, read once: (x + x) / 2 == x).
  for (int b = 0; b < n; ++b) {
    const int nb = c.nodes[static_cast<std::size_t>(b)];
    const int rb = block_.row_of_node[static_cast<std::size_t>(nb)];
    const int cb = tensors_.column_of_node[static_cast<std::size_t>(nb)];
    const int sb = slot_[static_cast<std::size_t>(b)];
    for (int a = b; a < n; ++a) {
      if (!fresh_[static_cast<std::size_t>(a)] && !fresh_[static_cast<std::size_t>(b)]) continue;
      const int sa = slot_[static_cast<std::size_t>(a)];
      ++g_blocks_read_;
      const int na = c.nodes[static_cast<std::size_t>(a)];
      const int ra = block_.row_of_node[static_cast<std::size_t>(na)];
      const int ca = tensors_.column_of_node[static_cast<std::size_t>(na)];
      Eigen::Matrix3d v = block_.block3(ra, cb);
      if (!block_.symmetric || ra != ca || rb != cb) v = 0.5 * (v + block_.block3(rb, ca).transpose());
      guu_.block<3, 3>(3 * sa, 3 * sb) = v;
      guu_.block<3, 3>(3 * sb, 3 * sa) = v.transpose();
    }
  }
  // Corotational: W_ab = R_a G_ab R_b^T (symmetric like G: the lower half, mirrored); a one-half variant is not
  // symmetric and is warped block by block.
  if (rotations != nullptr) {
    for (int b = 0; b < n; ++b) {
      const Eigen::Matrix3d& rb = rotations[b];
      const int sb = slot_[static_cast<std::size_t>(b)];
      for (int a = halves == RotationHalves::kBoth ? b : 0; a < n; ++a) {
        const int sa = slot_[static_cast<std::size_t>(a)];
        const Eigen::Matrix3d w = warp_block(rotations[a], guu_.block<3, 3>(3 * sa, 3 * sb), rb, halves);
        wuu_.block<3, 3>(3 * sa, 3 * sb) = w;
        if (halves == RotationHalves::kBoth && a != b) wuu_.block<3, 3>(3 * sb, 3 * sa) = w.transpose();
      }
    }
    w_ = &wuu_;
  }
  // M_pq = sum_i sum_j w_pi w_qj G_ij for p <= q, mirrored: first H_q(u) = sum_j w_qj W_uj at the union nodes
  // u < U_q (U_q: 1 + the highest union node of patches 0..q; a union listed in patch order, as the contact builds
  // it, makes that about half the union on average), then M_pq = sum_i w_pi H_q(i).
  int used = 0;  // U_q
  for (int q = 0; q < c.patch_count; ++q) {
    const int q0 = c.patch_start[static_cast<std::size_t>(q)], q1 = c.patch_start[static_cast<std::size_t>(q + 1)];
    for (int f = q0; f < q1; ++f) used = std::max(used, c.entry_node[static_cast<std::size_t>(f)] + 1);
    for (int u = 0; u < used; ++u) {
      Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
      for (int f = q0; f < q1; ++f)
        h.noalias() += c.entry_weight[static_cast<std::size_t>(f)] * blk(u, c.entry_node[static_cast<std::size_t>(f)]);
      h_[static_cast<std::size_t>(u)] = h;
    }
    for (int p = 0; p <= q; ++p) {
      const int p0 = c.patch_start[static_cast<std::size_t>(p)], p1 = c.patch_start[static_cast<std::size_t>(p + 1)];
      Eigen::Matrix3d mpq = Eigen::Matrix3d::Zero();
      for (int e = p0; e < p1; ++e)
        mpq.noalias() += c.entry_weight[static_cast<std::size_t>(e)] *
                         h_[static_cast<std::size_t>(c.entry_node[static_cast<std::size_t>(e)])];
      if (p == q && halves == RotationHalves::kBoth) mpq = (0.5 * (mpq + mpq.transpose())).eval();
      if (p == q) {
        const double nn = c.near_normal[static_cast<std::size_t>(p)], nt = c.near_tangent[static_cast<std::size_t>(p)];
        if (nn != 0 || nt != 0) {
          const Eigen::Vector3d& axis = c.near_axis[static_cast<std::size_t>(p)];
          mpq.noalias() += nt * Eigen::Matrix3d::Identity() + (nn - nt) * axis * axis.transpose();
        }
      }
      m_[static_cast<std::size_t>(p * kMaxPatches + q)] = mpq;
      m_[static_cast<std::size_t>(q * kMaxPatches + p)] = mpq.transpose();
    }
  }
  prepared_nodes_ = n;
  return ContactStatus::kOk;
}

ContactStatus PatchSolver::factor(const PatchConstraints& c, const unsigned char* enabled) noexcept {
  dependent_row_ = -1;
  enabled_count_ = 0;
  row_count_ = 0;
  if (c.row_count < 0 || c.row_count > kMaxPatchRows) return ContactStatus::kOverCapacity;
  for (int k = 0; k < c.row_count; ++k) {
    if (enabled != nullptr && enabled[k] == 0) continue;
    const int p = c.row_patch[static_cast<std::size_t>(k)];
    if (p < 0 || p >= c.patch_count) return ContactStatus::kInvalidNode;
    if (!c.row_direction[static_cast<std::size_t>(k)].allFinite()) return ContactStatus::kNonFinite;
    order_[static_cast<std::size_t>(enabled_count_++)] = k;
  }
  row_count_ = c.row_count;
  const int n = enabled_count_;
  double* a = a_.data();
  const Eigen::Index ld = a_.rows();
  for (int j = 0; j < n; ++j) {
    const int kj = order_[static_cast<std::size_t>(j)];
    const Eigen::Vector3d& dj = c.row_direction[static_cast<std::size_t>(kj)];
    const int pj = c.row_patch[static_cast<std::size_t>(kj)];
    for (int i = j; i < n; ++i) {
      const int ki = order_[static_cast<std::size_t>(i)];
      const int pi = c.row_patch[static_cast<std::size_t>(ki)];
      a[i + j * ld] = c.row_direction[static_cast<std::size_t>(ki)].dot(compliance(pi, pj) * dj);
    }
  }
  // In-place Cholesky; a pivot that lost all but 1e-9 of its diagonal marks a row dependent on the earlier ones.
  for (int j = 0; j < n; ++j) {
    double* cj = a + j * ld;
    const double original = cj[j];
    for (int k = 0; k < j; ++k) {
      const double ljk = a[j + k * ld];
      for (int i = j; i < n; ++i) cj[i] -= a[i + k * ld] * ljk;
    }
    const double d = cj[j];
    if (!(original > 0) || !std::isfinite(d) || !(d > 1e-9 * original)) {
      dependent_row_ = order_[static_cast<std::size_t>(j)];
      return ContactStatus::kNearSingular;
    }
    const double l = std::sqrt(d);
    cj[j] = l;
    for (int i = j + 1; i < n; ++i) cj[i] /= l;
  }
  return ContactStatus::kOk;
}

void PatchSolver::solve(const double* b, double* mu) const noexcept {
  const int n = enabled_count_;
  const double* a = a_.data();
  const Eigen::Index ld = a_.rows();
  std::array<double, kMaxPatchRows> y{};
  for (int j = 0; j < n; ++j) y[static_cast<std::size_t>(j)] = b[order_[static_cast<std::size_t>(j)]];
  llt_solve_in_place(a, ld, n, y.data());
  for (int k = 0; k < row_count_; ++k) mu[k] = 0;  // rows not enabled get 0
  for (int j = 0; j < n; ++j) mu[order_[static_cast<std::size_t>(j)]] = y[static_cast<std::size_t>(j)];
}

void PatchSolver::node_forces(const PatchConstraints& c, const double* mu, Eigen::Vector3d* lambda) const noexcept {
  for (int u = 0; u < c.node_count; ++u) lambda[u].setZero();
  for (int k = 0; k < c.row_count; ++k) {
    if (mu[k] == 0) continue;
    const int p = c.row_patch[static_cast<std::size_t>(k)];
    const Eigen::Vector3d f = mu[k] * c.row_direction[static_cast<std::size_t>(k)];
    for (int e = c.patch_start[static_cast<std::size_t>(p)]; e < c.patch_start[static_cast<std::size_t>(p + 1)]; ++e)
      lambda[c.entry_node[static_cast<std::size_t>(e)]] += c.entry_weight[static_cast<std::size_t>(e)] * f;
  }
}

Eigen::Vector3d PatchSolver::union_displacement(int u, const Eigen::Vector3d* lambda, int n) const noexcept {
  Eigen::Vector3d out = Eigen::Vector3d::Zero();
  if (u < 0 || u >= prepared_nodes_) return out;
  for (int v = 0; v < n && v < prepared_nodes_; ++v) out.noalias() += blk(u, v) * lambda[v];
  return out;
}

void PatchSolver::union_displacements(const Eigen::Vector3d* lambda, int n, Eigen::Vector3d* out) noexcept {
  n = std::min(n, prepared_nodes_);
  const int m = 3 * slot_end_;
  // Slots no union node holds carry no force (their blocks may be stale, but they are finite: 0 x G = 0).
  slot_in_.head(m).setZero();
  for (int u = 0; u < n; ++u) slot_in_.segment<3>(3 * slot_[static_cast<std::size_t>(u)]) += lambda[u];
  slot_out_.head(m).noalias() = w_->topLeftCorner(m, m) * slot_in_.head(m);
  for (int u = 0; u < n; ++u) out[u] = slot_out_.segment<3>(3 * slot_[static_cast<std::size_t>(u)]);
}

}  // namespace surgsim::compliance
