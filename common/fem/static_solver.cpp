#include "fem/static_solver.h"

#include <Eigen/Cholesky>
#include <Eigen/IterativeLinearSolvers>
#include <algorithm>
#include <cmath>
#include <map>

#include "core/error.h"

using namespace surgsim::core;

namespace surgsim::fem {

const char* to_string(SolveMethod method) { return method == SolveMethod::kDirect ? "direct" : "cg"; }

SolveMethod parse_solve_method(const std::string& text) {
  if (text == "direct") return SolveMethod::kDirect;
  if (text == "cg") return SolveMethod::kCg;
  throw_error("unknown solve method '", text, "' (expected direct or cg)");
}

std::vector<std::pair<int, double>> imposed_dof_values(const FixedSet& fixed,
                                                       const std::vector<ImposedDisplacement>& imposed) {
  const int n = fixed.node_count();
  std::map<int, double> by_dof;  // global dof -> value
  for (const auto& im : imposed) {
    if (im.node < 0 || im.node >= n)
      throw_error("imposed node ", im.node, " is out of range: the mesh has ", n, " nodes (0..", n - 1, ")");
    if ((im.components & 7) == 0) throw_error("imposed node ", im.node, ": no component selected");
    for (int c = 0; c < 3; ++c) {
      if (!(im.components & (1u << c))) continue;
      const double v = im.value[c];
      if (!std::isfinite(v)) throw_error("imposed node ", im.node, ": non-finite displacement component ", "xyz"[c]);
      const int dof = 3 * im.node + c;
      if (fixed.dof_fixed(dof))
        throw_error("imposed node ", im.node, ": component ", "xyz"[c],
                    " is fixed (clamped at zero); remove it from the imposed set or from the fixed set");
      auto [it, inserted] = by_dof.emplace(dof, v);
      if (!inserted && it->second != v)
        throw_error("imposed node ", im.node, ": component ", "xyz"[c], " imposed twice with different values (",
                    it->second, " and ", v, ")");
    }
  }
  return {by_dof.begin(), by_dof.end()};
}

namespace {

// The imposed components in free-dof numbering, sorted by free index, with their values.
struct Constraints {
  std::vector<int> dofs;   // free-dof indices, ascending
  Eigen::VectorXd values;  // m
  std::vector<int> nodes;  // nodes with an imposed component, ascending
};

Constraints gather(const ElasticModel& model, const std::vector<ImposedDisplacement>& imposed) {
  Constraints c;
  const auto by_dof = imposed_dof_values(model.fixed, imposed);
  c.values.resize(static_cast<Eigen::Index>(by_dof.size()));
  for (const auto& [dof, v] : by_dof) {
    c.values[static_cast<Eigen::Index>(c.dofs.size())] = v;
    c.dofs.push_back(model.fixed.free_index()[static_cast<std::size_t>(dof)]);
    if (c.nodes.empty() || c.nodes.back() != dof / 3) c.nodes.push_back(dof / 3);
  }
  return c;
}

// Scatters free-dof displacements and multipliers into a solution.
void fill_solution(const ElasticModel& model, const Constraints& c, const Eigen::VectorXd& u_free,
                   const Eigen::VectorXd& lambda, StaticSolution& out) {
  const int n = model.node_count();
  out.displacement.setZero(n, 3);
  const auto& dofs = model.fixed.free_dofs();
  for (std::size_t f = 0; f < dofs.size(); ++f)
    out.displacement(dofs[f] / 3, dofs[f] % 3) = u_free[static_cast<Eigen::Index>(f)];
  out.imposed_nodes = c.nodes;
  out.reaction.setZero(static_cast<Eigen::Index>(c.nodes.size()), 3);
  for (std::size_t k = 0; k < c.dofs.size(); ++k) {
    const int dof = dofs[static_cast<std::size_t>(c.dofs[k])];
    const auto row = std::lower_bound(c.nodes.begin(), c.nodes.end(), dof / 3) - c.nodes.begin();
    out.reaction(row, dof % 3) = lambda[static_cast<Eigen::Index>(k)];
  }
  out.total_reaction = out.reaction.colwise().sum().transpose();
}

}  // namespace

StaticSolver::StaticSolver(const ElasticModel& model, const StaticSolverOptions& options)
    : model_(model), options_(options) {
  if (options_.method == SolveMethod::kDirect) cholmod_ = std::make_unique<CholmodSolver>(model_.k_ff);
  if (options_.method == SolveMethod::kCg && !(options_.cg_tolerance > 0))
    throw_error("CG tolerance must be positive, got ", options_.cg_tolerance);
}

StaticSolver::~StaticSolver() = default;

StaticSolution StaticSolver::solve(const std::vector<ImposedDisplacement>& imposed) {
  const Constraints c = gather(model_, imposed);
  const Eigen::Index nf = model_.fixed.free_dof_count();
  const Eigen::Index m = static_cast<Eigen::Index>(c.dofs.size());
  StaticSolution out;
  if (m == 0) {
    fill_solution(model_, c, Eigen::VectorXd::Zero(nf), Eigen::VectorXd(), out);
    return out;
  }

  if (options_.method == SolveMethod::kDirect) {
    // Schur system S = C K_ff^-1 C^T, built from blocks of unit right-hand sides.
    Eigen::MatrixXd s(m, m);
    const Eigen::Index block = 192;
    Eigen::MatrixXd e, x;
    for (Eigen::Index j0 = 0; j0 < m; j0 += block) {
      const Eigen::Index nc = std::min(block, m - j0);
      e.setZero(nf, nc);
      for (Eigen::Index j = 0; j < nc; ++j) e(c.dofs[static_cast<std::size_t>(j0 + j)], j) = 1;
      x.resize(nf, nc);
      cholmod_->solve(e, x);
      for (Eigen::Index i = 0; i < m; ++i) s.block(i, j0, 1, nc) = x.row(c.dofs[static_cast<std::size_t>(i)]);
    }
    s = 0.5 * (s + s.transpose()).eval();
    Eigen::LLT<Eigen::MatrixXd> llt(s);
    if (llt.info() != Eigen::Success)
      throw_error("reference solve: the constraint (Schur) system is not positive definite");
    const Eigen::VectorXd lambda = llt.solve(c.values);
    // u = K_ff^-1 C^T lambda.
    Eigen::VectorXd f = Eigen::VectorXd::Zero(nf);
    for (Eigen::Index k = 0; k < m; ++k) f[c.dofs[static_cast<std::size_t>(k)]] = lambda[k];
    Eigen::VectorXd u(nf);
    cholmod_->solve(f, u);
    out.residual = (model_.k_ff * u - f).norm() / std::max(f.norm(), 1e-300);
    fill_solution(model_, c, u, lambda, out);
    return out;
  }

  // CG on the reduced system: eliminate the imposed dofs.
  std::vector<int> reduced(static_cast<std::size_t>(nf), -1);  // free dof -> unknown index, or -1 when imposed
  std::vector<char> imposed_flag(static_cast<std::size_t>(nf), 0);
  for (int d : c.dofs) imposed_flag[static_cast<std::size_t>(d)] = 1;
  int ni = 0;
  for (Eigen::Index f = 0; f < nf; ++f)
    if (!imposed_flag[static_cast<std::size_t>(f)]) reduced[static_cast<std::size_t>(f)] = ni++;
  std::vector<int> cpos(static_cast<std::size_t>(nf), -1);
  for (std::size_t k = 0; k < c.dofs.size(); ++k) cpos[static_cast<std::size_t>(c.dofs[k])] = static_cast<int>(k);

  std::vector<Eigen::Triplet<double>> tii;
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(ni);
  tii.reserve(static_cast<std::size_t>(model_.k_ff.nonZeros()));
  for (Eigen::Index j = 0; j < nf; ++j)
    for (Eigen::SparseMatrix<double>::InnerIterator it(model_.k_ff, j); it; ++it) {
      const int ri = reduced[static_cast<std::size_t>(it.row())];
      if (ri < 0) continue;
      const int rj = reduced[static_cast<std::size_t>(j)];
      if (rj >= 0)
        tii.emplace_back(ri, rj, it.value());
      else
        rhs[ri] -= it.value() * c.values[cpos[static_cast<std::size_t>(j)]];
    }
  Eigen::SparseMatrix<double> kii(ni, ni);
  kii.setFromTriplets(tii.begin(), tii.end());
  Eigen::ConjugateGradient<Eigen::SparseMatrix<double>, Eigen::Lower | Eigen::Upper> cg;
  cg.setTolerance(options_.cg_tolerance);
  cg.setMaxIterations(options_.cg_max_iterations > 0 ? options_.cg_max_iterations : 10 * std::max(ni, 1));
  cg.compute(kii);
  Eigen::VectorXd ui = Eigen::VectorXd::Zero(ni);
  if (ni > 0 && rhs.squaredNorm() > 0) {
    ui = cg.solve(rhs);
    out.iterations = static_cast<int>(cg.iterations());
    out.residual = cg.error();
    out.converged = cg.info() == Eigen::Success;
  }
  Eigen::VectorXd u(nf);
  for (Eigen::Index f = 0; f < nf; ++f) {
    const int r = reduced[static_cast<std::size_t>(f)];
    u[f] = r >= 0 ? ui[r] : c.values[cpos[static_cast<std::size_t>(f)]];
  }
  // lambda = (K_ff u) at the imposed dofs.
  Eigen::VectorXd lambda(m);
  for (Eigen::Index k = 0; k < m; ++k) {
    const int d = c.dofs[static_cast<std::size_t>(k)];
    double sum = 0;
    for (Eigen::SparseMatrix<double>::InnerIterator it(model_.k_ff, d); it; ++it) sum += it.value() * u[it.row()];
    lambda[k] = sum;  // K_ff symmetric: column d = row d
  }
  fill_solution(model_, c, u, lambda, out);
  return out;
}

}  // namespace surgsim::fem
