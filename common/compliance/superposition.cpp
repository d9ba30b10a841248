#include "compliance/superposition.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "fem/dense_llt.h"

using namespace surgsim::core;
using namespace surgsim::fem;

namespace surgsim::compliance {

const char* to_string(ContactStatus status) {
  switch (status) {
    case ContactStatus::kOk: return "ok";
    case ContactStatus::kOverCapacity: return "over capacity";
    case ContactStatus::kInvalidNode: return "invalid node";
    case ContactStatus::kFixedNode: return "contact on a fixed node";
    case ContactStatus::kNotContactable: return "node not contactable";
    case ContactStatus::kNotInBlock: return "node not a row of the tensor block";
    case ContactStatus::kNonFinite: return "non-finite input";
    case ContactStatus::kNearSingular: return "near-singular G_CC";
  }
  return "?";
}

ContactStatus contact_node_status(const Tensors& t, const TensorBlock& b, int node) noexcept {
  if (node < 0 || node >= t.node_count) return ContactStatus::kInvalidNode;
  if (t.fixed_mask[static_cast<std::size_t>(node)] != 0) return ContactStatus::kFixedNode;
  if (t.column_of_node[static_cast<std::size_t>(node)] < 0) return ContactStatus::kNotContactable;
  if (b.row_of_node[static_cast<std::size_t>(node)] < 0) return ContactStatus::kNotInBlock;
  return ContactStatus::kOk;
}

namespace {

// Validated, merged contacts written into caller storage of `capacity` entries. No allocation.
struct Merge {
  int count = 0;
  int merged = 0;
  double spread = 0;
  int bad = -1;
};

ContactStatus merge_contacts(const Tensors& t, const TensorBlock& b, const Contact* contacts, int m, int capacity,
                             int* nodes, Eigen::Vector3d* disp, int* counts, Merge& r) noexcept {
  r = Merge();
  if (m < 0 || (m > 0 && contacts == nullptr)) return ContactStatus::kInvalidNode;
  for (int i = 0; i < m; ++i) {
    const int node = contacts[i].node;
    r.bad = i;
    if (node < 0 || node >= t.node_count) return ContactStatus::kInvalidNode;
    if (!contacts[i].displacement.allFinite()) return ContactStatus::kNonFinite;
    if (const ContactStatus st = contact_node_status(t, b, node); st != ContactStatus::kOk) return st;
    int l = 0;
    while (l < r.count && nodes[l] != node) ++l;
    if (l < r.count) {
      disp[l] += contacts[i].displacement;
      ++counts[l];
      ++r.merged;
      continue;
    }
    if (r.count >= capacity) return ContactStatus::kOverCapacity;
    nodes[r.count] = node;
    disp[r.count] = contacts[i].displacement;
    counts[r.count] = 1;
    ++r.count;
  }
  r.bad = -1;
  if (r.merged > 0) {
    for (int l = 0; l < r.count; ++l) disp[l] /= counts[l];
    for (int i = 0; i < m; ++i) {
      int l = 0;
      while (nodes[l] != contacts[i].node) ++l;
      if (counts[l] > 1) r.spread = std::max(r.spread, (contacts[i].displacement - disp[l]).norm());
    }
  }
  return ContactStatus::kOk;
}

}  // namespace

Superposition::Superposition(const Tensors& tensors, const std::string& block_name, int capacity,
                             double near_singular_rcond)
    : tensors_(tensors),
      block_([&]() -> const TensorBlock& {
        const TensorBlock* b = tensors.find(block_name);
        if (!b) throw_error("superposition: the tensors have no block '", block_name, "'");
        return *b;
      }()),
      capacity_(capacity),
      near_singular_rcond_(near_singular_rcond) {
  if (capacity < 1 || capacity > kMaxContacts)
    throw_error("superposition: contact capacity must be 1..", kMaxContacts, ", got ", capacity);
  gcc_.setZero(3 * capacity, 3 * capacity);
  rhs_.setZero(3 * capacity);
}

namespace {

// 1-norm of the symmetric n x n matrix whose lower triangle is in `a`; `colsum` holds n entries (scratch).
double symmetric_norm1(const double* a, Eigen::Index ld, int n, double* colsum) noexcept {
  for (int j = 0; j < n; ++j) colsum[j] = 0;
  for (int j = 0; j < n; ++j) {
    const double* cj = a + j * ld;
    colsum[j] += std::abs(cj[j]);
    for (int i = j + 1; i < n; ++i) {
      colsum[j] += std::abs(cj[i]);
      colsum[i] += std::abs(cj[i]);  // a_ji = a_ij
    }
  }
  double norm = 0;
  for (int j = 0; j < n; ++j) norm = std::max(norm, colsum[j]);
  return norm;
}

// Estimate of ||A^-1||_1 for A = L L^T (L in the lower triangle of `a`): Hager's method with Higham's refinements
// (Higham 1988, LAPACK dlacn2 as used by dpocon), A^-1 being symmetric. At most 5 iterations plus Higham's
// alternating test vector, each one or two solves with L (O(n^2)); a lower bound on ||A^-1||_1, in practice within
// a factor of 3 of it. `x` (n) is scratch, `sign` (n) too. No allocation.
double inverse_norm1_estimate(const double* a, Eigen::Index ld, int n, double* x, signed char* sign) noexcept {
  const auto norm1 = [&]() {
    double s = 0;
    for (int i = 0; i < n; ++i) s += std::abs(x[i]);
    return s;
  };
  const auto argmax_abs = [&]() {
    int j = 0;
    for (int i = 1; i < n; ++i)
      if (std::abs(x[i]) > std::abs(x[j])) j = i;
    return j;
  };
  for (int i = 0; i < n; ++i) x[i] = 1.0 / n;
  llt_solve_in_place(a, ld, n, x);
  double est = norm1();
  if (n == 1) return est;
  for (int i = 0; i < n; ++i) {
    sign[i] = x[i] >= 0 ? 1 : -1;
    x[i] = sign[i];
  }
  llt_solve_in_place(a, ld, n, x);  // z = A^-T sign(y) = A^-1 sign(y)
  int j = argmax_abs();
  for (int iter = 2;; ++iter) {
    for (int i = 0; i < n; ++i) x[i] = 0;
    x[j] = 1;
    llt_solve_in_place(a, ld, n, x);  // column j of A^-1
    const double old = est;
    est = norm1();
    bool same_sign = true;
    for (int i = 0; i < n; ++i) same_sign = same_sign && (x[i] >= 0 ? 1 : -1) == sign[i];
    if (same_sign || est <= old) {
      est = std::max(est, old);
      break;
    }
    for (int i = 0; i < n; ++i) {
      sign[i] = x[i] >= 0 ? 1 : -1;
      x[i] = sign[i];
    }
    llt_solve_in_place(a, ld, n, x);
    const int last = j;
    j = argmax_abs();
    if (std::abs(x[last]) == std::abs(x[j]) || iter >= 5) break;
  }
  // Higham's alternating vector catches the matrices where the iteration stalls.
  for (int i = 0; i < n; ++i) x[i] = (i % 2 == 0 ? 1.0 : -1.0) * (1.0 + static_cast<double>(i) / (n - 1));
  llt_solve_in_place(a, ld, n, x);
  return std::max(est, 2.0 * norm1() / (3.0 * n));
}

}  // namespace

ContactStatus Superposition::solve(const Contact* contacts, int m, ContactSolution& out) noexcept {
  return solve(contacts, m, nullptr, 0, out);
}

ContactStatus Superposition::solve(const Contact* contacts, int m, const Load* loads, int load_count,
                                   ContactSolution& out) noexcept {
  Merge r;
  out.status = merge_contacts(tensors_, block_, contacts, m, capacity_, out.nodes.data(), out.displacement.data(),
                              merged_count_.data(), r);
  out.merged_duplicates = r.merged;
  out.duplicate_spread = r.spread;
  out.bad_input = r.bad;
  out.tool_force.setZero();
  out.rcond = 1;
  const auto fail = [&](ContactStatus s) {
    out.status = s;
    out.count = 0;
    out.tool_force.setZero();
    return s;
  };
  if (out.status != ContactStatus::kOk) return fail(out.status);
  // The known loads: each on a node with a precomputed column, finite (checked before any work).
  for (int j = 0; j < load_count; ++j) {
    const Load& load = loads[j];
    const bool column = load.node >= 0 && load.node < tensors_.node_count &&
                        tensors_.column_of_node[static_cast<std::size_t>(load.node)] >= 0;
    if (!column || !load.force.allFinite()) {
      out.bad_input = m + j;
      return fail(column ? ContactStatus::kNonFinite : ContactStatus::kNotContactable);
    }
  }
  const int n = 3 * r.count;
  out.count = r.count;
  if (n == 0) return ContactStatus::kOk;

  // G_CC (lower triangle, symmetrized from both stored halves; a symmetric block gives the same entry twice).
  const Eigen::Index ld = gcc_.rows();
  double* a = gcc_.data();
  for (int lj = 0; lj < r.count; ++lj) {
    const int rj = block_.row_of_node[static_cast<std::size_t>(out.nodes[static_cast<std::size_t>(lj)])];
    const int cj = tensors_.column_of_node[static_cast<std::size_t>(out.nodes[static_cast<std::size_t>(lj)])];
    for (int li = lj; li < r.count; ++li) {
      const int ri = block_.row_of_node[static_cast<std::size_t>(out.nodes[static_cast<std::size_t>(li)])];
      const int ci = tensors_.column_of_node[static_cast<std::size_t>(out.nodes[static_cast<std::size_t>(li)])];
      const Eigen::Matrix3d gij = block_.block3(ri, cj), gji = block_.block3(rj, ci);
      for (int b = 0; b < 3; ++b)
        for (int c = 0; c < 3; ++c) {
          const int i = 3 * li + c, j = 3 * lj + b;
          if (i < j) continue;
          a[i + j * ld] = 0.5 * (gij(c, b) + gji(b, c));
        }
    }
  }

  // ||G_CC||_1 before the factorization overwrites it (rhs_ as scratch: it is filled below).
  const double gcc_norm1 = symmetric_norm1(a, ld, n, rhs_.data());

  // In-place Cholesky G_CC = L L^T (right-looking; column-major inner loops).
  for (int j = 0; j < n; ++j) {
    double* cj = a + j * ld;
    const double d = cj[j];
    if (!(d > 0) || !std::isfinite(d)) {
      out.rcond = 0;
      return fail(ContactStatus::kNearSingular);
    }
    const double l = std::sqrt(d);
    cj[j] = l;
    for (int i = j + 1; i < n; ++i) cj[i] /= l;
    for (int k = j + 1; k < n; ++k) {
      double* ck = a + k * ld;
      const double lkj = cj[k];
      for (int i = k; i < n; ++i) ck[i] -= cj[i] * lkj;
    }
  }
  // rcond = 1 / (||G_CC||_1 est||G_CC^-1||_1), as LAPACK's dpocon. (The Cholesky diagonal alone cannot tell: an
  // even diagonal, (min/max)^2 = 1, is compatible with any conditioning.)
  std::array<signed char, 3 * kMaxContacts> sign;
  const double inv_norm1 = inverse_norm1_estimate(a, ld, n, rhs_.data(), sign.data());
  out.rcond = gcc_norm1 > 0 && inv_norm1 > 0 ? 1.0 / (gcc_norm1 * inv_norm1) : 0.0;
  if (!std::isfinite(out.rcond)) out.rcond = 0;
  if (!(out.rcond >= near_singular_rcond_)) return fail(ContactStatus::kNearSingular);

  // lambda = L^-T L^-1 (u* - G_CB f_B): the loads' displacement at each contact node taken off what it must reach.
  double* y = rhs_.data();
  for (int l = 0; l < r.count; ++l)
    for (int c = 0; c < 3; ++c) y[3 * l + c] = out.displacement[static_cast<std::size_t>(l)][c];
  for (int j = 0; j < load_count; ++j) {
    const int cb = tensors_.column_of_node[static_cast<std::size_t>(loads[j].node)];
    for (int l = 0; l < r.count; ++l) {
      const int rk = block_.row_of_node[static_cast<std::size_t>(out.nodes[static_cast<std::size_t>(l)])];
      const Eigen::Vector3d u = block_.block3(rk, cb) * loads[j].force;
      for (int c = 0; c < 3; ++c) y[3 * l + c] -= u[c];
    }
  }
  llt_solve_in_place(a, ld, n, y);
  for (int l = 0; l < r.count; ++l) {
    const auto ul = static_cast<std::size_t>(l);
    out.lambda[ul] = Eigen::Vector3d(y[3 * l], y[3 * l + 1], y[3 * l + 2]);
    out.tool_force -= out.lambda[ul];
    // u~_l = G_kk lambda_l.
    const int rk = block_.row_of_node[static_cast<std::size_t>(out.nodes[ul])];
    const int ck = tensors_.column_of_node[static_cast<std::size_t>(out.nodes[ul])];
    const Eigen::Matrix3d gkk = block_.block3(rk, ck);
    for (int a = 0; a < 3; ++a) {
      double sum = 0;
      for (int b = 0; b < 3; ++b) sum += gkk(a, b) * out.lambda[ul][b];
      out.corrected[ul][a] = sum;
    }
  }
  if (!out.tool_force.allFinite()) return fail(ContactStatus::kNearSingular);
  return ContactStatus::kOk;
}

bool Superposition::displacement(int node, const ContactSolution& solution, Eigen::Vector3d& u) const noexcept {
  if (solution.status != ContactStatus::kOk) return false;
  return displacement(node, solution.nodes.data(), solution.lambda.data(), solution.count, u) == ContactStatus::kOk;
}

ContactStatus Superposition::displacement(int node, const int* contact_nodes, const Eigen::Vector3d* lambda, int m,
                                          Eigen::Vector3d& u) const noexcept {
  u.setZero();
  if (node < 0 || node >= tensors_.node_count) return ContactStatus::kInvalidNode;
  const int r = block_.row_of_node[static_cast<std::size_t>(node)];
  if (r < 0)
    return tensors_.fixed_mask[static_cast<std::size_t>(node)] == 7 ? ContactStatus::kOk : ContactStatus::kNotInBlock;
  for (int l = 0; l < m; ++l) {
    const int k = contact_nodes[l];
    if (k < 0 || k >= tensors_.node_count) return ContactStatus::kInvalidNode;
    const int c = tensors_.column_of_node[static_cast<std::size_t>(k)];
    if (c < 0) return ContactStatus::kNotContactable;
    if (!lambda[l].allFinite()) return ContactStatus::kNonFinite;
    const Eigen::Matrix3d grc = block_.block3(r, c);
    for (int b = 0; b < 3; ++b)
      for (int a = 0; a < 3; ++a) u[a] += grc(a, b) * lambda[l][b];
  }
  return ContactStatus::kOk;
}

ContactStatus Superposition::displacements(const int* contact_nodes, const Eigen::Vector3d* lambda, int m,
                                           Eigen::Ref<Eigen::VectorXd> out) const noexcept {
  out.setZero();
  if (out.size() != 3 * static_cast<Eigen::Index>(block_.row_count())) return ContactStatus::kInvalidNode;
  for (int l = 0; l < m; ++l) {
    const int k = contact_nodes[l];
    if (k < 0 || k >= tensors_.node_count) return ContactStatus::kInvalidNode;
    if (tensors_.column_of_node[static_cast<std::size_t>(k)] < 0) return ContactStatus::kNotContactable;
    if (!lambda[l].allFinite()) return ContactStatus::kNonFinite;
  }
  for (int l = 0; l < m; ++l) {
    const Eigen::Index c = tensors_.column_of_node[static_cast<std::size_t>(contact_nodes[l])];
    for (int b = 0; b < 3; ++b) {
      const double s = lambda[l][b];
      if (s == 0) continue;
      if (block_.symmetric) {  // column 3c + b of the packed half: rows from column c down, then row c across
        for (Eigen::Index i = 0; i < out.size(); ++i) out[i] += block_.at(i, 3 * c + b) * s;
      } else if (block_.g.size()) {
        out.noalias() += block_.g.col(3 * c + b) * s;
      } else {
        out.noalias() += block_.g_float.col(3 * c + b).cast<double>() * s;
      }
    }
  }
  return ContactStatus::kOk;
}

ContactStatus Superposition::lambda_from_corrected(const int* contact_nodes, const Eigen::Vector3d* corrected, int m,
                                                   Eigen::Vector3d* lambda) const noexcept {
  for (int l = 0; l < m; ++l) {
    lambda[l].setZero();
    const int k = contact_nodes[l];
    if (k < 0 || k >= tensors_.node_count) return ContactStatus::kInvalidNode;
    const int c = tensors_.column_of_node[static_cast<std::size_t>(k)];
    if (c < 0) return ContactStatus::kNotContactable;
    const int r = block_.row_of_node[static_cast<std::size_t>(k)];
    if (r < 0) return ContactStatus::kNotInBlock;
    if (!corrected[l].allFinite()) return ContactStatus::kNonFinite;
    const Eigen::Matrix3d gkk = block_.block3(r, c);
    // 3x3 SPD solve via the fixed-size LDLT-free inverse (no allocation for fixed sizes).
    Eigen::Matrix3d inv;
    bool invertible = false;
    double det = 0;
    gkk.computeInverseAndDetWithCheck(inv, det, invertible, 0.0);
    if (!invertible || !(det > 0)) return ContactStatus::kNearSingular;
    lambda[l] = inv * corrected[l];
  }
  return ContactStatus::kOk;
}

PaperTensors::PaperTensors(const Tensors& tensors, const std::string& block_name)
    : tensors_(tensors), block_([&]() -> const TensorBlock& {
        const TensorBlock* b = tensors.find(block_name);
        if (!b) throw_error("paper tensors: the tensors have no block '", block_name, "'");
        return *b;
      }()) {
  const int s = tensors.column_count();
  tf_.resize(static_cast<std::size_t>(s));
  for (int c = 0; c < s; ++c) {
    const int k = tensors.contact_nodes[static_cast<std::size_t>(c)];
    const int r = block_.row_of_node[static_cast<std::size_t>(k)];
    if (r < 0) throw_error("paper tensors: contact node ", k, " is not a row of block '", block_name, "'");
    tf_[static_cast<std::size_t>(c)] = block_.block3(r, c).inverse();  // T^f_k = G_kk^-1
  }
  // T^u(:, k) = G(:, k) G_kk^-1.
  tu_.resize(3 * static_cast<Eigen::Index>(block_.row_count()), 3 * static_cast<Eigen::Index>(s));
  Eigen::MatrixXd g3(tu_.rows(), 3);
  for (int c = 0; c < s; ++c) {
    for (int b = 0; b < 3; ++b) block_.column(3 * c + b, g3.col(b).data());
    tu_.middleCols<3>(3 * c).noalias() = g3 * tf_[static_cast<std::size_t>(c)];
  }
}

PaperTensors::Solution PaperTensors::solve(const std::vector<Contact>& contacts) const {
  Solution out;
  const int m = static_cast<int>(contacts.size());
  std::vector<int> nodes(contacts.size()), counts(contacts.size());
  std::vector<Eigen::Vector3d> disp(contacts.size());
  Merge r;
  out.status =
      merge_contacts(tensors_, block_, contacts.data(), m, std::max(m, 1), nodes.data(), disp.data(), counts.data(), r);
  if (out.status != ContactStatus::kOk) return out;
  nodes.resize(static_cast<std::size_t>(r.count));
  disp.resize(static_cast<std::size_t>(r.count));
  const int n = 3 * r.count;
  // Mutual influence M (M_lj = T^u_{k_l k_j}) and M u~ = u*.
  Eigen::MatrixXd mm(n, n);
  Eigen::VectorXd ustar(n);
  for (int l = 0; l < r.count; ++l) {
    const int rl = block_.row_of_node[static_cast<std::size_t>(nodes[static_cast<std::size_t>(l)])];
    ustar.segment<3>(3 * l) = disp[static_cast<std::size_t>(l)];
    for (int j = 0; j < r.count; ++j) {
      const int cj = tensors_.column_of_node[static_cast<std::size_t>(nodes[static_cast<std::size_t>(j)])];
      mm.block<3, 3>(3 * l, 3 * j) = tu_.block<3, 3>(3 * rl, 3 * cj);
    }
  }
  Eigen::PartialPivLU<Eigen::MatrixXd> lu(mm);
  if (n > 0 && !(lu.rcond() > 1e-14)) {
    out.status = ContactStatus::kNearSingular;
    return out;
  }
  const Eigen::VectorXd corrected = n > 0 ? Eigen::VectorXd(lu.solve(ustar)) : Eigen::VectorXd();
  out.nodes = nodes;
  out.displacement = disp;
  for (int l = 0; l < r.count; ++l) {
    const Eigen::Vector3d ut = corrected.segment<3>(3 * l);
    out.corrected.push_back(ut);
    const int c = tensors_.column_of_node[static_cast<std::size_t>(nodes[static_cast<std::size_t>(l)])];
    out.lambda.push_back(tf_[static_cast<std::size_t>(c)] * ut);
    out.tool_force -= out.lambda.back();
  }
  return out;
}

Eigen::VectorXd PaperTensors::displacements(const std::vector<int>& contact_nodes,
                                            const std::vector<Eigen::Vector3d>& corrected) const {
  Eigen::VectorXd u = Eigen::VectorXd::Zero(tu_.rows());
  for (std::size_t l = 0; l < contact_nodes.size(); ++l) {
    const int c = tensors_.column_of_node[static_cast<std::size_t>(contact_nodes[l])];
    if (c < 0) throw_error("paper tensors: node ", contact_nodes[l], " is not contactable");
    u.noalias() += tu_.middleCols<3>(3 * c) * corrected[l];
  }
  return u;
}

}  // namespace surgsim::compliance
