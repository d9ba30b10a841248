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
}

Eigen::Matrix3d PatchSolver::g(int a, int b) const noexcept { return w_->block<3, 3>(3 * a, 3 * b); }

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
  // G of the union nodes, symmetrized from both stored halves (as Superposition::solve). The first `kept` nodes are
  // those of the last read in the same order: their blocks are in guu_ already.
  int kept = 0;
  while (kept < n && kept < g_count_ &&
         g_nodes_[static_cast<std::size_t>(kept)] == c.nodes[static_cast<std::size_t>(kept)])
    ++kept;
  g_count_ = 0;  // until the read below is complete
  for (int b = 0; b < n; ++b) {
    const int nb = c.nodes[static_cast<std::size_t>(b)];
    const int rb = block_.row_of_node[static_cast<std::size_t>(nb)];
    const int cb = tensors_.column_of_node[static_cast<std::size_t>(nb)];
    for (int a = std::max(b, kept); a < n; ++a) {
      ++g_blocks_read_;
      const int na = c.nodes[static_cast<std::size_t>(a)];
      const int ra = block_.row_of_node[static_cast<std::size_t>(na)];
      const int ca = tensors_.column_of_node[static_cast<std::size_t>(na)];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
          const double v = 0.5 * (block_.at(3 * ra + i, 3 * cb + j) + block_.at(3 * rb + j, 3 * ca + i));
          guu_(3 * a + i, 3 * b + j) = v;
          guu_(3 * b + j, 3 * a + i) = v;
        }
    }
  }
  for (int u = 0; u < n; ++u) g_nodes_[static_cast<std::size_t>(u)] = c.nodes[static_cast<std::size_t>(u)];
  g_count_ = n;
  // Corotational: W_ab = R_a G_ab R_b^T (symmetric like G: the lower half, mirrored); a one-half variant is not
  // symmetric and is warped block by block.
  if (rotations != nullptr) {
    for (int b = 0; b < n; ++b) {
      const Eigen::Matrix3d& rb = rotations[b];
      for (int a = halves == RotationHalves::kBoth ? b : 0; a < n; ++a) {
        const Eigen::Matrix3d w = warp_block(rotations[a], guu_.block<3, 3>(3 * a, 3 * b), rb, halves);
        wuu_.block<3, 3>(3 * a, 3 * b) = w;
        if (halves == RotationHalves::kBoth && a != b) wuu_.block<3, 3>(3 * b, 3 * a) = w.transpose();
      }
    }
    w_ = &wuu_;
  }
  const Eigen::MatrixXd& w = *w_;
  // M_pq = sum_i sum_j w_pi w_qj G_ij: first H_q(u) = sum_j w_qj G_{u j}, then M_pq = sum_i w_pi H_q(i).
  for (int q = 0; q < c.patch_count; ++q) {
    const int q0 = c.patch_start[static_cast<std::size_t>(q)], q1 = c.patch_start[static_cast<std::size_t>(q + 1)];
    for (int p = 0; p <= q; ++p) {
      const int p0 = c.patch_start[static_cast<std::size_t>(p)], p1 = c.patch_start[static_cast<std::size_t>(p + 1)];
      Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
      for (int e = p0; e < p1; ++e) {
        const int ue = c.entry_node[static_cast<std::size_t>(e)];
        Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
        for (int f = q0; f < q1; ++f)
          h.noalias() += c.entry_weight[static_cast<std::size_t>(f)] *
                         w.block<3, 3>(3 * ue, 3 * c.entry_node[static_cast<std::size_t>(f)]);
        m.noalias() += c.entry_weight[static_cast<std::size_t>(e)] * h;
      }
      if (p == q && halves == RotationHalves::kBoth) m = (0.5 * (m + m.transpose())).eval();
      if (p == q) {
        const double nn = c.near_normal[static_cast<std::size_t>(p)], nt = c.near_tangent[static_cast<std::size_t>(p)];
        if (nn != 0 || nt != 0) {
          const Eigen::Vector3d& axis = c.near_axis[static_cast<std::size_t>(p)];
          m.noalias() += nt * Eigen::Matrix3d::Identity() + (nn - nt) * axis * axis.transpose();
        }
      }
      m_[static_cast<std::size_t>(p * kMaxPatches + q)] = m;
      m_[static_cast<std::size_t>(q * kMaxPatches + p)] = m.transpose();
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
  for (int v = 0; v < n && v < prepared_nodes_; ++v) out.noalias() += w_->block<3, 3>(3 * u, 3 * v) * lambda[v];
  return out;
}

}  // namespace surgsim::compliance
