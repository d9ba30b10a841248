// The reference ("normal") static solve of the 1998 paper: a linear-elastic organ with imposed displacements on
// some nodes, by Lagrange multipliers (paper eq. 2). Used to validate the precomputed tensors, by surgsim-solve and
// by the benchmarks. Not for the haptic loop (it allocates).
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "fem/cholmod_solver.h"
#include "fem/fem.h"

namespace surgsim::fem {

/// How linear systems in K_ff are solved.
enum class SolveMethod {
  kDirect,  // CHOLMOD Cholesky of K_ff (factored once)
  kCg,      // conjugate gradient (Jacobi preconditioner) to a relative residual tolerance, as in the paper
};
const char* to_string(SolveMethod method);
/// "direct" | "cg"; throws surgsim::core::Error otherwise.
SolveMethod parse_solve_method(const std::string& text);

/// A displacement imposed on some components of one node.
struct ImposedDisplacement {
  int node = -1;                                    // 0-based node index
  Eigen::Vector3d value = Eigen::Vector3d::Zero();  // m; only the imposed components are read
  std::uint8_t components = 7;                      // bit c set: component c (x, y, z) imposed; others stay free
};

/// The imposed components as (global dof 3 node + c, value), ascending by dof; repeats with equal values merged.
/// Throws surgsim::core::Error for a node out of range, a non-finite value, no component selected, a component that is
/// fixed, or the same component imposed twice with different values. Shared by StaticSolver and HyperelasticSolver.
std::vector<std::pair<int, double>> imposed_dof_values(const FixedSet& fixed,
                                                       const std::vector<ImposedDisplacement>& imposed);

struct StaticSolverOptions {
  SolveMethod method = SolveMethod::kDirect;
  double cg_tolerance = 1e-10;  // relative residual |b - A x| / |b|
  int cg_max_iterations = 0;    // 0: 10 x the number of unknowns
};

struct StaticSolution {
  Eigen::MatrixX3d displacement;   // #V x 3, m (fixed dofs are 0, imposed ones equal their value)
  std::vector<int> imposed_nodes;  // #I nodes with an imposed component, ascending
  Eigen::MatrixX3d reaction;       // #I x 3, N: force the constraint applies on the organ at imposed_nodes[i]
                                   // (the Lagrange multiplier; 0 on components left free)
  Eigen::Vector3d total_reaction = Eigen::Vector3d::Zero();  // N, sum of reaction rows (the tool feels minus this)
  int iterations = 0;                                        // CG iterations (0 for direct)
  double residual = 0;    // relative residual of the solve in K (CG: of the reduced system)
  bool converged = true;  // false when CG stopped at its iteration limit
};

/// Solves K u = f with u = u* on imposed dofs, u = 0 on fixed dofs and no other load. Direct: K_ff is factored once
/// (constructor); each solve builds the Schur system S = C K_ff^-1 C^T (m x m for m imposed components, columns in
/// blocks), lambda = S^-1 u*, u = K_ff^-1 C^T lambda. CG: the imposed dofs are eliminated and the reduced system
/// K_II u_I = -K_IC u* is solved by CG; lambda = K_CI u_I + K_CC u* -- the same multipliers. The model must outlive
/// the solver.
class StaticSolver {
 public:
  explicit StaticSolver(const ElasticModel& model, const StaticSolverOptions& options = StaticSolverOptions());
  ~StaticSolver();
  StaticSolver(const StaticSolver&) = delete;
  StaticSolver& operator=(const StaticSolver&) = delete;

  /// Throws surgsim::core::Error for a node out of range, a non-finite value, no component selected, a component that
  /// is fixed, or the same component imposed twice with different values (repeats with equal values are merged).
  StaticSolution solve(const std::vector<ImposedDisplacement>& imposed);

  const StaticSolverOptions& options() const { return options_; }

 private:
  const ElasticModel& model_;
  StaticSolverOptions options_;
  std::unique_ptr<CholmodSolver> cholmod_;  // direct only
};

}  // namespace surgsim::fem
