#include "nonlinear/multirate.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::fem;
using namespace surgsim::compliance;

namespace surgsim::nonlinear {

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

}  // namespace

NonlinearTracker::NonlinearTracker(const HyperelasticSolver& solver, std::vector<int> surface_nodes,
                                   const MultirateOptions& options)
    : solver_(solver), model_(solver.model()), surface_nodes_(std::move(surface_nodes)), options_(options) {
  if (options_.iterations_per_cycle < 1)
    throw_error("multirate: iterations_per_cycle must be >= 1, got ", options_.iterations_per_cycle);
  if (options_.corrections_per_cycle < 0)
    throw_error("multirate: corrections_per_cycle must be >= 0, got ", options_.corrections_per_cycle);
  if (!(options_.residual_tolerance > 0)) throw_error("multirate: residual_tolerance must be positive");
  if (!(options_.max_step > 0)) throw_error("multirate: max_step must be positive");
  if (!(options_.move_tolerance > 0)) throw_error("multirate: move_tolerance must be positive");
  if (!(options_.publish_tolerance > 0)) throw_error("multirate: publish_tolerance must be positive");
  if (!(options_.max_extrapolation > 0)) throw_error("multirate: max_extrapolation must be positive");
  const int n = model_.node_count();
  for (int node : surface_nodes_)
    if (node < 0 || node >= n) throw_error("multirate: surface node ", node, " out of range [0, ", n, ")");
  for (int i = 0; i < 3; ++i) {
    TrackerSnapshot& s = snapshots_.slot(i);
    s.stiffness = Eigen::MatrixXd::Zero(3 * kMaxContacts, 3 * kMaxContacts);
    s.surface = Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(surface_nodes_.size()));
  }
  reset();
}

void NonlinearTracker::reset() {
  u_ = Eigen::VectorXd::Zero(3 * model_.node_count());
  sys_ = ReducedSystem();
  dof_contact_.clear();
  analysed_ = false;
  stuck_ = false;
  step_cut_ = 1;
}

TrackerCycle NonlinearTracker::cycle(const ContactTargets& targets) {
  const auto t_start = Clock::now();
  TrackerCycle out;
  const int n = model_.node_count();
  if (targets.count < 0 || targets.count > kMaxContacts)
    throw_error("multirate: ", targets.count, " contact nodes, at most kMaxContacts = ", kMaxContacts);
  // The imposed dofs (components of the fixed set stay 0), ascending, and where each comes from in the targets.
  std::vector<std::pair<int, int>> dofs;
  for (int k = 0; k < targets.count; ++k) {
    const int node = targets.nodes[static_cast<std::size_t>(k)];
    if (node < 0 || node >= n) throw_error("multirate: contact node ", node, " out of range [0, ", n, ")");
    for (int j = 0; j < k; ++j)
      if (targets.nodes[static_cast<std::size_t>(j)] == node)
        throw_error("multirate: contact node ", node, " repeated");
    if (!targets.u[static_cast<std::size_t>(k)].allFinite())
      throw_error("multirate: contact node ", node, " has a non-finite target displacement");
    for (int c = 0; c < 3; ++c)
      if (!model_.fixed.dof_fixed(3 * node + c)) dofs.emplace_back(3 * node + c, 3 * k + c);
  }
  std::sort(dofs.begin(), dofs.end());
  std::vector<int> imposed(dofs.size());
  for (std::size_t j = 0; j < dofs.size(); ++j) imposed[j] = dofs[j].first;
  if (imposed != sys_.imposed_dofs || sys_.unknown.empty()) {
    sys_ = ReducedSystem::make(model_, imposed);
    out.set_changed = true;
    analysed_ = false;
  }
  dof_contact_.resize(dofs.size());
  for (std::size_t j = 0; j < dofs.size(); ++j) {
    dof_contact_[j] = dofs[j].second;
    sys_.target[static_cast<Eigen::Index>(j)] =
        targets.u[static_cast<std::size_t>(dofs[j].second / 3)][dofs[j].second % 3];
  }
  const int m = static_cast<int>(imposed.size());
  ++cycles_;
  if (m == 0) {
    // Nothing held: the rest shape is the equilibrium.
    u_.setZero();
    x_.setZero(sys_.count, 1);
    s_.resize(0, 0);
    out.converged = true;
    out.published = true;
    publish(targets, x_, true, 0);
    out.total_ms = ms_since(t_start);
    return out;
  }

  const auto relative_residual = [&]() {
    ri_ = sys_.restrict(f_);
    return ri_.norm() / std::max(sys_.imposed_norm(f_), options_.force_floor);
  };
  for (int it = 0; it < options_.iterations_per_cycle; ++it) {
    auto t0 = Clock::now();
    if (!solver_.tangent_stiffness(u_, kt_) || !solver_.internal_force(u_, f_)) {
      out.failure = "the tracked state inverts a tet";  // not reached from an accepted state
      break;
    }
    sys_.refresh(kt_);
    const double r0 = relative_residual();
    // Move the contact dofs towards their targets only from a state near equilibrium (else this iteration is a
    // correction), by at most max_step per node: each predictor starts from a converged state, as load steps do.
    bool at_target = true;
    double largest = 0, node_sq = 0;
    for (int j = 0; j < m; ++j) {
      const int d = imposed[static_cast<std::size_t>(j)];
      const double dc = sys_.target[j] - u_[d];
      if (dc != 0) at_target = false;
      node_sq += dc * dc;
      if (j + 1 == m || imposed[static_cast<std::size_t>(j + 1)] / 3 != d / 3) {
        largest = std::max(largest, std::sqrt(node_sq));
        node_sq = 0;
      }
    }
    const bool move = !at_target && (r0 <= options_.move_tolerance || stuck_);
    const double scale = move ? std::min(1.0, step_cut_ * options_.max_step / largest) : 0.0;
    const int columns = options_.contact_stiffness ? m : 0;
    b_.setZero(sys_.count, 1 + columns);
    rhs_ = -ri_;  // the predictor's (K_ii du_i = -r_i - K_ic dc) or the correction's right side
    for (int j = 0; j < m; ++j) {
      const int d = imposed[static_cast<std::size_t>(j)];
      const double dc = scale * (sys_.target[j] - u_[d]);
      if (dc != 0) sys_.subtract_coupling(kt_, d, dc, rhs_);
      if (columns == 0) continue;
      for (Eigen::SparseMatrix<double>::InnerIterator e(kt_, d); e; ++e) {
        const int ri = sys_.unknown[static_cast<std::size_t>(e.row())];
        if (ri >= 0) b_(ri, 1 + j) = e.value();  // K_ic (K_T symmetric)
      }
    }
    b_.col(0) = rhs_;
    out.assemble_ms += ms_since(t0);
    t0 = Clock::now();
    // CHOLMOD keeps the analysis of this contact set; a tangent that is not positive definite goes to LDL^T.
    bool factored = false;
    try {
      if (!analysed_) {
        chol_.analyze(sys_.kii);
        analysed_ = true;
        chol_.factorize();
      } else {
        chol_.refactorize(sys_.kii);
      }
      factored = true;
    } catch (const Error&) {
    }
    out.factor_ms += ms_since(t0);
    t0 = Clock::now();
    bool solved = false;
    if (factored) {
      x_.resize(b_.rows(), b_.cols());
      chol_.solve(b_, x_);
      solved = x_.allFinite();
    } else {
      solved = solve_reduced_tangent(sys_.kii, b_, x_, out.ldlt_fallback);
    }
    out.solve_ms += ms_since(t0);
    if (!solved) {
      out.failure = "singular tangent";
      break;
    }
    t0 = Clock::now();
    ++out.iterations;
    // The contact stiffness of this tangent: S = K_cc - K_ci K_ii^-1 K_ic.
    s_.resize(m, m);
    for (int j = 0; j < m; ++j)
      for (int l = 0; l < m; ++l)
        s_(j, l) = kt_.coeff(imposed[static_cast<std::size_t>(j)], imposed[static_cast<std::size_t>(l)]);
    if (columns == 0)
      s_.setZero();
    else
      s_.noalias() -= b_.rightCols(m).transpose() * x_.rightCols(m);
    s_ = 0.5 * (s_ + s_.transpose()).eval();
    out.solve_ms += ms_since(t0);
    t0 = Clock::now();
    if (at_target && r0 <= options_.residual_tolerance) {
      out.converged = true;
      out.residual = r0;
      out.published = true;
      publish(targets, x_, true, r0);
      out.assemble_ms += ms_since(t0);
      break;
    }
    bool stepped = false;
    if (move) {
      // Predictor: the contact dofs by `scale` of the way to their targets (halved while it inverts a tet), the
      // unknowns with them.
      u_keep_ = u_;
      f_keep_ = f_;
      double alpha = 1;
      for (int h = 0; h <= options_.max_predictor_halvings && !stepped; ++h, alpha *= 0.5) {
        v_ = u_;
        for (int j = 0; j < m; ++j) {
          const int d = imposed[static_cast<std::size_t>(j)];
          v_[d] = alpha * scale == 1 ? sys_.target[j] : u_[d] + alpha * scale * (sys_.target[j] - u_[d]);
        }
        sys_.add_unknowns(x_.col(0), alpha, v_);
        if (solver_.internal_force(v_, fv_)) {
          u_.swap(v_);
          f_.swap(fv_);
          stepped = true;
        } else {
          ++out.predictor_halvings;
        }
      }
      if (!stepped) out.failure = "every cut of the predictor inverts a tet";
      stuck_ = false;
    } else {
      dx_ = x_.col(0);
      stepped = solver_.line_search(sys_, dx_, ri_.norm(), u_, f_, trial_, ft_).accepted;
      if (!stepped) out.failure = "the line search found no decrease of the residual";
      stuck_ = !stepped;
    }
    double r1 = relative_residual();
    // Modified Newton corrections with this factorization (no new tangent): cheap, and they keep the state near
    // equilibrium while the targets move every cycle.
    for (int k = 0; stepped && factored && k < options_.corrections_per_cycle && r1 > options_.residual_tolerance;
         ++k) {
      rhs_ = -ri_;
      dx_.resize(rhs_.size());
      chol_.solve(rhs_, dx_);
      if (!dx_.allFinite() || !solver_.line_search(sys_, dx_, ri_.norm(), u_, f_, trial_, ft_).accepted) break;
      ++out.corrections;
      r1 = relative_residual();
    }
    if (move && stepped) {
      // A predictor that left the state far from equilibrium (too long a step for the tangent) is taken back: from
      // there the next tangents can be indefinite and the state lost (lift_90 in 0.5 s). The next ones are shorter.
      if (r1 > options_.publish_tolerance) {
        u_.swap(u_keep_);
        f_.swap(f_keep_);
        r1 = relative_residual();
        step_cut_ = std::max(step_cut_ * 0.5, 1.0 / 64);
        out.step_rejected = true;
      } else {
        step_cut_ = std::min(1.0, 2 * step_cut_);
      }
    }
    out.residual = r1;
    out.assemble_ms += ms_since(t0);
    if (!stepped || it + 1 == options_.iterations_per_cycle) {
      // The state (moved or not) with this factorization's S, stale by the step just taken: published as not
      // converged. At equilibrium, the next iteration or cycle refactors there and publishes it as converged. A state
      // far from equilibrium is not published: its linearly corrected f_c and its S can be far off.
      if (r1 <= options_.publish_tolerance) {
        out.published = true;
        publish(targets, x_, false, r1);
      }
      break;
    }
  }
  out.total_ms = ms_since(t_start);
  return out;
}

void NonlinearTracker::publish(const ContactTargets& targets, const Eigen::MatrixXd& x, bool converged,
                               double residual) {
  TrackerSnapshot& s = snapshots_.back();
  const int m = static_cast<int>(sys_.imposed_dofs.size());
  s.cycle = cycles_;
  s.count = targets.count;
  s.converged = converged;
  s.residual = residual;
  for (int k = 0; k < targets.count; ++k) {
    const int node = targets.nodes[static_cast<std::size_t>(k)];
    s.nodes[static_cast<std::size_t>(k)] = node;
    s.u[static_cast<std::size_t>(k)] = u_.segment<3>(3 * node);
    s.reaction[static_cast<std::size_t>(k)].setZero();
  }
  s.stiffness.topLeftCorner(3 * targets.count, 3 * targets.count).setZero();
  if (m > 0) {
    // f_c corrected for the out-of-balance force left on the unknowns: f_c + K_ci du_i, du_i = -K_ii^-1 r_i.
    const Eigen::VectorXd correction =
        x.cols() == 1 + m ? Eigen::VectorXd(x.rightCols(m).transpose() * ri_) : Eigen::VectorXd::Zero(m);
    for (int j = 0; j < m; ++j) {
      const int cj = dof_contact_[static_cast<std::size_t>(j)];
      s.reaction[static_cast<std::size_t>(cj / 3)][cj % 3] =
          f_[sys_.imposed_dofs[static_cast<std::size_t>(j)]] - correction[j];
      for (int l = 0; l < m; ++l) s.stiffness(cj, dof_contact_[static_cast<std::size_t>(l)]) = s_(j, l);
    }
  }
  for (std::size_t i = 0; i < surface_nodes_.size(); ++i)
    s.surface.segment<3>(3 * static_cast<Eigen::Index>(i)) = u_.segment<3>(3 * surface_nodes_[i]);
  bool finite = s.surface.allFinite() && s.stiffness.topLeftCorner(3 * targets.count, 3 * targets.count).allFinite();
  for (int k = 0; k < targets.count; ++k)
    finite =
        finite && s.u[static_cast<std::size_t>(k)].allFinite() && s.reaction[static_cast<std::size_t>(k)].allFinite();
  s.valid = finite;
  snapshots_.publish();
}

int snapshot_forces(const TrackerSnapshot& snapshot, const int* nodes, const Eigen::Vector3d* displacement, int m,
                    double max_extrapolation, Eigen::Vector3d* lambda, bool* held, double& largest) noexcept {
  largest = 0;
  for (int l = 0; l < m; ++l) held[l] = false;
  const int n = snapshot.count;
  if (!snapshot.valid || m < 0 || m > kMaxContacts || n < 0 || n > kMaxContacts) return 0;
  if (snapshot.stiffness.rows() < 3 * n || snapshot.stiffness.cols() < 3 * n) return 0;
  // Each contact's place in the snapshot (each snapshot node matched once) and du there (0 at the snapshot's nodes no
  // contact names: they contribute nothing).
  std::array<double, 3 * kMaxContacts> du{};
  std::array<bool, kMaxContacts> used{};
  std::array<int, kMaxContacts> at{};
  int matched = 0;
  for (int l = 0; l < m; ++l) {
    int j = 0;
    while (j < n && (snapshot.nodes[static_cast<std::size_t>(j)] != nodes[l] || used[static_cast<std::size_t>(j)])) ++j;
    at[static_cast<std::size_t>(l)] = j < n ? j : -1;
    if (j == n) continue;
    used[static_cast<std::size_t>(j)] = true;
    Eigen::Vector3d d = displacement[l] - snapshot.u[static_cast<std::size_t>(j)];
    if (!d.allFinite()) return 0;
    const double len = d.norm();
    largest = std::max(largest, len);
    if (len > max_extrapolation) d *= max_extrapolation / len;
    for (int c = 0; c < 3; ++c) du[static_cast<std::size_t>(3 * j + c)] = d[c];
    ++matched;
  }
  for (int l = 0; l < m; ++l) {
    const int j = at[static_cast<std::size_t>(l)];
    if (j < 0) continue;
    Eigen::Vector3d f = snapshot.reaction[static_cast<std::size_t>(j)];
    for (int r = 0; r < 3; ++r) {
      double acc = 0;
      for (int col = 0; col < 3 * n; ++col)
        acc += snapshot.stiffness(3 * j + r, col) * du[static_cast<std::size_t>(col)];
      f[r] += acc;
    }
    if (!f.allFinite()) {
      for (int k = 0; k < m; ++k) held[k] = false;
      return 0;
    }
    lambda[l] = f;
    held[l] = true;
  }
  return matched;
}

bool local_contact_forces(const TrackerSnapshot& snapshot, const Contact* contacts, int m, double max_extrapolation,
                          ContactSolution& out) noexcept {
  out.count = 0;
  out.tool_force.setZero();
  out.merged_duplicates = 0;
  out.duplicate_spread = 0;
  out.bad_input = -1;
  if (m < 0 || m > kMaxContacts || m != snapshot.count) return false;
  std::array<int, kMaxContacts> nodes{};
  std::array<Eigen::Vector3d, kMaxContacts> displacement{};
  std::array<bool, kMaxContacts> held{};
  displacement.fill(Eigen::Vector3d::Zero());
  for (int i = 0; i < m; ++i) {
    nodes[static_cast<std::size_t>(i)] = contacts[i].node;
    displacement[static_cast<std::size_t>(i)] = contacts[i].displacement;
  }
  double largest = 0;
  if (snapshot_forces(snapshot, nodes.data(), displacement.data(), m, max_extrapolation, out.lambda.data(), held.data(),
                      largest) != m)
    return false;
  Eigen::Vector3d total = Eigen::Vector3d::Zero();
  for (int i = 0; i < m; ++i) {
    out.nodes[static_cast<std::size_t>(i)] = contacts[i].node;
    out.displacement[static_cast<std::size_t>(i)] = contacts[i].displacement;
    out.corrected[static_cast<std::size_t>(i)] = contacts[i].displacement;
    total += out.lambda[static_cast<std::size_t>(i)];
  }
  if (!total.allFinite()) return false;
  out.count = m;
  out.status = ContactStatus::kOk;
  out.rcond = 1;
  out.tool_force = -total;
  return true;
}

MultirateSource MultirateForce::evaluate(const Contact* contacts, int m, ContactSolution& out) noexcept {
  snapshots_.take();
  if (local_contact_forces(snapshots_.front(), contacts, m, max_extrapolation_, out))
    return MultirateSource::kNonlinear;
  ++fallbacks_;
  linear_.solve(contacts, m, out);
  return MultirateSource::kLinearFallback;
}

}  // namespace surgsim::nonlinear
