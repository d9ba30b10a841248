#include "fem/hyperelastic.h"

#include <Eigen/LU>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "fem/cholmod_solver.h"
#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::fem {

LameParameters lame_parameters(const Material& material) {
  check_material(material);
  const double e = material.young_modulus, nu = material.poisson_ratio;
  return {e / (2 * (1 + nu)), e * nu / ((1 + nu) * (1 - 2 * nu))};
}

double neo_hookean_energy_density(const Eigen::Matrix3d& f, const LameParameters& lame) {
  const double log_j = std::log(f.determinant());
  return 0.5 * lame.mu * (f.squaredNorm() - 3) - lame.mu * log_j + 0.5 * lame.lambda * log_j * log_j;
}

Eigen::Matrix3d neo_hookean_stress(const Eigen::Matrix3d& f, const LameParameters& lame) {
  const Eigen::Matrix3d f_inv_t = f.inverse().transpose();
  return lame.mu * (f - f_inv_t) + lame.lambda * std::log(f.determinant()) * f_inv_t;
}

Eigen::Matrix<double, 9, 9> neo_hookean_tangent(const Eigen::Matrix3d& f, const LameParameters& lame) {
  // dP = mu dF + (mu - lambda ln J) F^-T dF^T F^-T + lambda tr(F^-1 dF) F^-T; with H = F^-1:
  // dP_ij / dF_kl = mu d_ik d_jl + (mu - lambda ln J) H_li H_jk + lambda H_ji H_lk.
  const Eigen::Matrix3d h = f.inverse();
  const double c = lame.mu - lame.lambda * std::log(f.determinant());
  Eigen::Matrix<double, 9, 9> a;
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i)
      for (int l = 0; l < 3; ++l)
        for (int k = 0; k < 3; ++k)
          a(i + 3 * j, k + 3 * l) =
              (i == k && j == l ? lame.mu : 0.0) + c * h(l, i) * h(j, k) + lame.lambda * h(j, i) * h(l, k);
  return a;
}

const char* to_string(HyperelasticStatus status) {
  switch (status) {
    case HyperelasticStatus::kConverged: return "converged";
    case HyperelasticStatus::kInverted: return "inverted";
    case HyperelasticStatus::kNotConverged: return "not_converged";
  }
  return "unknown";
}

namespace {

// vec(dF) = B u_e for the 12 dofs of a tet (node a, component k): dF = e_k grad_a^T, so B(k + 3 l, 3 a + k) = grad_a,l.
Eigen::Matrix<double, 9, 12> gradient_operator(const Eigen::Matrix<double, 4, 3>& grad) {
  Eigen::Matrix<double, 9, 12> b = Eigen::Matrix<double, 9, 12>::Zero();
  for (int a = 0; a < 4; ++a)
    for (int k = 0; k < 3; ++k)
      for (int l = 0; l < 3; ++l) b(k + 3 * l, 3 * a + k) = grad(a, l);
  return b;
}

// Deformation gradient of tet t: F = I + U^T G, U the 4 x 3 corner displacements.
Eigen::Matrix3d deformation_gradient(const TetMesh& mesh, int t, const Eigen::Matrix<double, 4, 3>& grad,
                                     const Eigen::VectorXd& u) {
  Eigen::Matrix3d f = Eigen::Matrix3d::Identity();
  for (int a = 0; a < 4; ++a) f += u.segment<3>(3 * mesh.tets(t, a)) * grad.row(a);
  return f;
}

}  // namespace

HyperelasticSolver::HyperelasticSolver(const ElasticModel& model, const HyperelasticOptions& options)
    : model_(model), options_(options), lame_(lame_parameters(model.material)) {
  // Each tet's own material (a region's, else the base): the model's resolved one, or resolved here for a model put
  // together by hand.
  const ElementMaterials elements =
      model_.elements.element.empty() ? element_materials(*model_.mesh, model_.material) : model_.elements;
  std::vector<LameParameters> lames;
  for (const Material& m : elements.materials) lames.push_back(lame_parameters(m));
  for (int i : elements.element) element_lame_.push_back(lames[static_cast<std::size_t>(i)]);
  if (options_.load_steps < 1) throw_error("hyperelastic: load_steps must be >= 1, got ", options_.load_steps);
  if (options_.max_iterations < 2)
    throw_error("hyperelastic: max_iterations must be >= 2 (a predictor and a correction), got ",
                options_.max_iterations);
  if (!(options_.residual_tolerance > 0)) throw_error("hyperelastic: residual_tolerance must be positive");
  if (!model_.k.isCompressed()) throw_error("hyperelastic: the model's stiffness must be in compressed storage");
  const TetMesh& mesh = *model_.mesh;
  const int tets = static_cast<int>(mesh.tets.rows());
  grad_.resize(static_cast<std::size_t>(tets));
  volume_.resize(static_cast<std::size_t>(tets));
  block_pos_.resize(static_cast<std::size_t>(tets) * 48);
  const int* outer = model_.k.outerIndexPtr();
  const int* inner = model_.k.innerIndexPtr();
  for (int t = 0; t < tets; ++t) {
    // Reference shape-function gradients: rows of edges^-1 for corners 1..3, minus their sum for corner 0.
    Eigen::Matrix3d edges;
    for (int a = 0; a < 3; ++a)
      edges.col(a) = (mesh.nodes.row(mesh.tets(t, a + 1)) - mesh.nodes.row(mesh.tets(t, 0))).transpose();
    const double det = edges.determinant();
    const double scale = edges.colwise().norm().maxCoeff();
    if (!(det > 1e-14 * scale * scale * scale))
      throw_error("hyperelastic: tet ", t, " is degenerate or inverted in the rest shape (volume ", det / 6, " m^3)");
    const Eigen::Matrix3d inv = edges.inverse();
    auto& g = grad_[static_cast<std::size_t>(t)];
    g.bottomRows<3>() = inv;
    g.row(0) = -inv.colwise().sum();
    volume_[static_cast<std::size_t>(t)] = det / 6;
    // Where K(3 na + i, 3 nb + k) lives in the model's pattern (rows 3 na .. 3 na + 2 are contiguous in a column).
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        for (int k = 0; k < 3; ++k) {
          const int col = 3 * mesh.tets(t, b) + k, row = 3 * mesh.tets(t, a);
          const int* first = inner + outer[col];
          const int* last = inner + outer[col + 1];
          const int* it = std::lower_bound(first, last, row);
          if (last - it < 3 || it[0] != row || it[1] != row + 1 || it[2] != row + 2)
            throw_error("hyperelastic: the model's stiffness pattern lacks the block of nodes ", mesh.tets(t, a),
                        " and ", mesh.tets(t, b));
          block_pos_[static_cast<std::size_t>(t) * 48 + static_cast<std::size_t>((a * 4 + b) * 3 + k)] =
              static_cast<int>(it - inner);
        }
  }
}

bool HyperelasticSolver::internal_force(const Eigen::VectorXd& u, Eigen::VectorXd& f, double* energy,
                                        double* min_jacobian, int* worst_tet) const {
  const TetMesh& mesh = *model_.mesh;
  f.setZero(u.size());
  double e = 0, j_min = std::numeric_limits<double>::infinity();
  int worst = -1;
  bool ok = true;
  for (int t = 0; t < static_cast<int>(mesh.tets.rows()); ++t) {
    const auto& g = grad_[static_cast<std::size_t>(t)];
    const Eigen::Matrix3d fg = deformation_gradient(mesh, t, g, u);
    double j = fg.determinant();
    if (!std::isfinite(j)) j = -std::numeric_limits<double>::infinity();
    if (worst < 0 || j < j_min) {
      j_min = j;
      worst = t;
    }
    if (!(j > 0)) {
      ok = false;
      continue;
    }
    if (!ok) continue;  // keep scanning for the worst tet only
    const double v = volume_[static_cast<std::size_t>(t)];
    const LameParameters& lame = element_lame_[static_cast<std::size_t>(t)];
    if (energy) e += v * neo_hookean_energy_density(fg, lame);
    // f_a = V P grad_a.
    const Eigen::Matrix3d p = neo_hookean_stress(fg, lame);
    for (int a = 0; a < 4; ++a) f.segment<3>(3 * mesh.tets(t, a)) += v * p * g.row(a).transpose();
  }
  if (energy) *energy = e;
  if (min_jacobian) *min_jacobian = j_min;
  if (worst_tet) *worst_tet = worst;
  return ok && f.allFinite();
}

bool HyperelasticSolver::tangent_stiffness(const Eigen::VectorXd& u, Eigen::SparseMatrix<double>& k) const {
  const TetMesh& mesh = *model_.mesh;
  k = model_.k;
  std::fill(k.valuePtr(), k.valuePtr() + k.nonZeros(), 0.0);
  double* value = k.valuePtr();
  for (int t = 0; t < static_cast<int>(mesh.tets.rows()); ++t) {
    const auto& g = grad_[static_cast<std::size_t>(t)];
    const Eigen::Matrix3d fg = deformation_gradient(mesh, t, g, u);
    const double j = fg.determinant();
    if (!(j > 0) || !std::isfinite(j)) return false;
    // K_e = V B^T A B.
    const Eigen::Matrix<double, 9, 12> b = gradient_operator(g);
    const Eigen::Matrix<double, 12, 12> ke = volume_[static_cast<std::size_t>(t)] * b.transpose() *
                                             (neo_hookean_tangent(fg, element_lame_[static_cast<std::size_t>(t)]) * b);
    const int* pos = block_pos_.data() + static_cast<std::size_t>(t) * 48;
    for (int a = 0; a < 4; ++a)
      for (int bn = 0; bn < 4; ++bn)
        for (int kk = 0; kk < 3; ++kk) {
          double* dst = value + pos[(a * 4 + bn) * 3 + kk];
          for (int i = 0; i < 3; ++i) dst[i] += ke(3 * a + i, 3 * bn + kk);
        }
  }
  return k.coeffs().allFinite();
}

namespace {

enum class Failure { kNone, kInverted, kNotConverged };

}  // namespace

ReducedSystem ReducedSystem::make(const ElasticModel& model, const std::vector<int>& imposed_dofs) {
  const int ndof = 3 * model.node_count();
  ReducedSystem sys;
  sys.unknown.assign(static_cast<std::size_t>(ndof), -1);
  std::vector<char> is_imposed(static_cast<std::size_t>(ndof), 0);
  for (int d : imposed_dofs) is_imposed[static_cast<std::size_t>(d)] = 1;
  sys.imposed_dofs = imposed_dofs;
  sys.target = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(imposed_dofs.size()));
  for (int d = 0; d < ndof; ++d)
    if (!model.fixed.dof_fixed(d) && !is_imposed[static_cast<std::size_t>(d)])
      sys.unknown[static_cast<std::size_t>(d)] = sys.count++;
  sys.build(model.k);
  return sys;
}

void ReducedSystem::build(const Eigen::SparseMatrix<double>& pattern) {
  std::vector<Eigen::Index> outer(static_cast<std::size_t>(count) + 1, 0);
  std::vector<int> inner;
  kii_source.clear();
  for (Eigen::Index j = 0; j < pattern.outerSize(); ++j) {
    const int cj = unknown[static_cast<std::size_t>(j)];
    if (cj < 0) continue;
    for (Eigen::SparseMatrix<double>::InnerIterator it(pattern, j); it; ++it) {
      const int ri = unknown[static_cast<std::size_t>(it.row())];
      if (ri < 0) continue;
      inner.push_back(ri);
      kii_source.push_back(static_cast<int>(&it.value() - pattern.valuePtr()));
    }
    outer[static_cast<std::size_t>(cj) + 1] = static_cast<Eigen::Index>(inner.size());
  }
  kii.resize(count, count);
  kii.resizeNonZeros(static_cast<Eigen::Index>(inner.size()));
  std::copy(outer.begin(), outer.end(), kii.outerIndexPtr());
  std::copy(inner.begin(), inner.end(), kii.innerIndexPtr());
}

void ReducedSystem::refresh(const Eigen::SparseMatrix<double>& kt) {
  for (std::size_t e = 0; e < kii_source.size(); ++e) kii.valuePtr()[e] = kt.valuePtr()[kii_source[e]];
}

Eigen::VectorXd ReducedSystem::restrict(const Eigen::VectorXd& full) const {
  Eigen::VectorXd r(count);
  for (std::size_t d = 0; d < unknown.size(); ++d)
    if (unknown[d] >= 0) r[unknown[d]] = full[static_cast<Eigen::Index>(d)];
  return r;
}

double ReducedSystem::imposed_norm(const Eigen::VectorXd& full) const {
  double s = 0;
  for (int d : imposed_dofs) s += full[d] * full[d];
  return std::sqrt(s);
}

void ReducedSystem::subtract_coupling(const Eigen::SparseMatrix<double>& kt, int dof, double dc,
                                      Eigen::VectorXd& rhs) const {
  for (Eigen::SparseMatrix<double>::InnerIterator it(kt, dof); it; ++it) {
    const int ri = unknown[static_cast<std::size_t>(it.row())];
    if (ri >= 0) rhs[ri] -= it.value() * dc;  // K_T symmetric: column d = row d
  }
}

void ReducedSystem::add_unknowns(const Eigen::VectorXd& x, double alpha, Eigen::VectorXd& full) const {
  for (std::size_t d = 0; d < unknown.size(); ++d)
    if (unknown[d] >= 0) full[static_cast<Eigen::Index>(d)] += alpha * x[unknown[d]];
}

bool solve_reduced_tangent(const Eigen::SparseMatrix<double>& kii, const Eigen::Ref<const Eigen::MatrixXd>& b,
                           Eigen::MatrixXd& x, bool& ldlt_used) {
  x.resize(b.rows(), b.cols());
  try {
    CholmodSolver chol(kii);
    chol.solve(b, x);
    return x.allFinite();
  } catch (const Error&) {
    ldlt_used = true;
  }
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(kii);
  if (ldlt.info() != Eigen::Success) return false;
  x = ldlt.solve(b);
  return ldlt.info() == Eigen::Success && x.allFinite();
}

LineSearchOutcome HyperelasticSolver::line_search(const ReducedSystem& sys, const Eigen::VectorXd& du_i, double r,
                                                  Eigen::VectorXd& v, Eigen::VectorXd& f, Eigen::VectorXd& trial,
                                                  Eigen::VectorXd& ft) const {
  LineSearchOutcome out;
  double alpha = 1;
  for (int h = 0; h <= options_.max_line_search_halvings; ++h, alpha *= 0.5) {
    trial = v;
    sys.add_unknowns(du_i, alpha, trial);
    double jmin = 0;
    int worst = -1;
    if (!internal_force(trial, ft, nullptr, &jmin, &worst)) {
      out.bad_tet = worst;
      continue;
    }
    out.any_valid = true;
    if (sys.restrict(ft).norm() <= (1 - 1e-4 * alpha) * r) {
      out.accepted = true;
      v.swap(trial);
      f.swap(ft);
      out.min_jacobian = jmin;
      break;
    }
    ++out.halvings;
  }
  return out;
}

HyperelasticSolution HyperelasticSolver::solve(const std::vector<ImposedDisplacement>& imposed) const {
  const int n = model_.node_count();
  const int ndof = 3 * n;
  const auto dof_values = imposed_dof_values(model_.fixed, imposed);

  std::vector<int> imposed_dofs;
  for (const auto& dv : dof_values) imposed_dofs.push_back(dv.first);
  ReducedSystem sys = ReducedSystem::make(model_, imposed_dofs);
  for (std::size_t c = 0; c < dof_values.size(); ++c) sys.target[static_cast<Eigen::Index>(c)] = dof_values[c].second;

  HyperelasticSolution out;
  for (const auto& dv : dof_values)
    if (out.imposed_nodes.empty() || out.imposed_nodes.back() != dv.first / 3)
      out.imposed_nodes.push_back(dv.first / 3);
  Eigen::VectorXd u = Eigen::VectorXd::Zero(ndof);  // last converged state
  Eigen::VectorXd f(ndof);
  // Reactions on the imposed nodes from the internal force of a state.
  const auto reactions = [&](const Eigen::VectorXd& force, Eigen::MatrixX3d& r, Eigen::Vector3d& total) {
    r.setZero(static_cast<Eigen::Index>(out.imposed_nodes.size()), 3);
    for (int d : sys.imposed_dofs) {
      const auto row =
          std::lower_bound(out.imposed_nodes.begin(), out.imposed_nodes.end(), d / 3) - out.imposed_nodes.begin();
      r(row, d % 3) = force[d];
    }
    total = r.colwise().sum().transpose();
  };
  const auto finish = [&](double load_factor) {
    out.load_factor = load_factor;
    out.displacement = Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>(u.data(), n, 3);
    internal_force(u, f, nullptr, &out.min_jacobian);
    reactions(f, out.reaction, out.total_reaction);
    return out;
  };
  if (sys.imposed_dofs.empty() || sys.target.cwiseAbs().maxCoeff() == 0) return finish(1.0);

  const double nominal = 1.0 / options_.load_steps;
  double done = 0, ds = nominal;
  int cuts = 0;
  Eigen::SparseMatrix<double> kt;
  Eigen::VectorXd v, trial, ft, rhs;
  Eigen::MatrixXd du_i;
  while (done < 1) {
    HyperelasticStep step;
    step.load_factor = (1 - (done + ds) < 1e-12) ? 1.0 : done + ds;
    Failure failure = Failure::kNone;
    int bad_tet = -1;
    v = u;

    // Predictor: move the imposed dofs to their new values, the unknowns by the linearized response.
    if (!tangent_stiffness(v, kt) || !internal_force(v, f)) {
      failure = Failure::kInverted;  // cannot happen from a converged state; kept for safety
    } else {
      sys.refresh(kt);
      rhs = -sys.restrict(f);
      for (std::size_t c = 0; c < sys.imposed_dofs.size(); ++c) {
        const int d = sys.imposed_dofs[c];
        const double dc = step.load_factor * sys.target[static_cast<Eigen::Index>(c)] - v[d];
        sys.subtract_coupling(kt, d, dc, rhs);
        v[d] += dc;
      }
      if (!solve_reduced_tangent(sys.kii, rhs, du_i, step.ldlt_fallback)) {
        failure = Failure::kNotConverged;
        step.failure = "singular tangent in the predictor";
      } else {
        sys.add_unknowns(du_i.col(0), 1.0, v);
        ++step.iterations;
        if (!internal_force(v, f, nullptr, &step.min_jacobian, &bad_tet)) {
          failure = Failure::kInverted;
          step.failure = "the predictor inverts a tet";
        }
      }
    }

    // Newton corrections with a backtracking line search on |r_i|.
    while (failure == Failure::kNone) {
      const double r = sys.restrict(f).norm();
      step.force_scale = std::max(sys.imposed_norm(f), options_.force_floor);
      step.residuals.push_back(r);
      if (r <= options_.residual_tolerance * step.force_scale) break;  // converged
      if (step.iterations >= options_.max_iterations) {
        failure = Failure::kNotConverged;
        step.failure = "no convergence in " + std::to_string(options_.max_iterations) + " iterations";
        break;
      }
      if (!tangent_stiffness(v, kt)) {
        failure = Failure::kInverted;
        break;
      }
      sys.refresh(kt);
      if (!solve_reduced_tangent(sys.kii, -sys.restrict(f), du_i, step.ldlt_fallback)) {
        failure = Failure::kNotConverged;
        step.failure = "singular tangent";
        break;
      }
      ++step.iterations;
      const LineSearchOutcome ls = line_search(sys, du_i.col(0), r, v, f, trial, ft);
      step.line_search_halvings += ls.halvings;
      if (ls.accepted) step.min_jacobian = ls.min_jacobian;
      if (ls.bad_tet >= 0) bad_tet = ls.bad_tet;
      const bool accepted = ls.accepted, any_valid = ls.any_valid;
      if (!accepted) {
        failure = any_valid ? Failure::kNotConverged : Failure::kInverted;
        step.failure = any_valid ? "the line search found no decrease of the residual"
                                 : "every step of the line search inverts a tet";
      }
    }

    step.converged = failure == Failure::kNone;
    if (step.converged) {
      reactions(f, step.reaction, step.total_reaction);
      u = v;
      done = step.load_factor;
      out.total_iterations += step.iterations;
      out.steps.push_back(std::move(step));
      // Grow back towards the nominal increment after easy steps.
      if (out.steps.back().iterations <= 4) ds = std::min(nominal, 2 * ds);
      ds = std::min(ds, 1 - done);
      continue;
    }
    out.total_iterations += step.iterations;
    const double target = step.load_factor;
    const std::string why = step.failure;
    out.steps.push_back(std::move(step));
    if (++cuts > options_.max_step_cuts) {
      std::ostringstream msg;
      out.status = failure == Failure::kInverted ? HyperelasticStatus::kInverted : HyperelasticStatus::kNotConverged;
      msg << "neo-Hookean solve stopped at load factor " << done << " of 1: the increment to " << target << " failed ("
          << why << ") after " << options_.max_step_cuts << " cuts";
      if (out.status == HyperelasticStatus::kInverted && bad_tet >= 0) {
        out.inverted_tet = bad_tet;
        msg << "; tet " << bad_tet << " (nodes " << model_.mesh->tets.row(bad_tet) << ") inverts (det F <= 0)";
      }
      msg << "; reduce the imposed displacement or refine the mesh near the load";
      out.message = msg.str();
      return finish(done);
    }
    ds *= 0.5;
  }
  return finish(1.0);
}

}  // namespace surgsim::fem
