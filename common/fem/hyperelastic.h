// Geometrically non-linear static reference: a compressible neo-Hookean organ of P1 tetrahedra with imposed
// displacements on some nodes and fixed dofs, solved by Newton's method with load stepping and a line search. It is
// the reference the linear tensors and the quasi non-linear law (nonlinear_law.h) are measured against at large
// indentations; the material is the one config/curves was made from:
//   W(F) = mu/2 (tr(F^T F) - 3) - mu ln J + lambda/2 (ln J)^2,  J = det F,
//   mu = E / (2 (1 + nu)), lambda = E nu / ((1 + nu)(1 - 2 nu))   (the small-strain match to E, nu),
// so that for small displacements the solution is the linear StaticSolver's.
//
// Method. Unknowns are the free dofs that are not imposed. Each load increment moves the imposed dofs to
// s u* (s = load factor) with a linearized predictor (K_ii du_i = -r_i - K_ic du_c, full step), then corrects with
// Newton (K_ii du_i = -r_i) and a backtracking line search on |r_i| that also refuses any trial state with an inverted
// tet (J <= 0). The consistent tangent K_T = d f_int / du is assembled in the sparsity of the linear K and factored by
// CHOLMOD (Eigen's LDL^T when the tangent is not positive definite). A failed increment (an inversion in the predictor,
// no convergence, a singular tangent) is halved and retried from the last converged state. No body forces.
// Allocates: a reference for tests and benchmarks, not for the loops.
#pragma once
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <cstdint>
#include <string>
#include <vector>

#include "fem/fem.h"
#include "fem/static_solver.h"

namespace surgsim::fem {

/// Lame parameters (Pa) of the small-strain match to E, nu.
struct LameParameters {
  double mu = 0;      // Pa, E / (2 (1 + nu))
  double lambda = 0;  // Pa, E nu / ((1 + nu)(1 - 2 nu))
};
/// Throws surgsim::core::Error for a bad material (check_material).
LameParameters lame_parameters(const Material& material);

/// Compressible neo-Hookean energy density W(F) (J/m^3). Requires det F > 0 (not checked).
double neo_hookean_energy_density(const Eigen::Matrix3d& f, const LameParameters& lame);
/// First Piola-Kirchhoff stress P = dW/dF = mu (F - F^-T) + lambda ln J F^-T (Pa). Requires det F > 0.
Eigen::Matrix3d neo_hookean_stress(const Eigen::Matrix3d& f, const LameParameters& lame);
/// dP/dF (Pa) as 9 x 9: entry (i + 3 j, k + 3 l) = dP_ij / dF_kl (column-major vectorization of F and P).
/// Requires det F > 0.
Eigen::Matrix<double, 9, 9> neo_hookean_tangent(const Eigen::Matrix3d& f, const LameParameters& lame);

struct HyperelasticOptions {
  int load_steps = 10;                // equal increments of the imposed displacements before any cut, >= 1
  int max_step_cuts = 12;             // halvings of failed increments allowed over the whole solve
  int max_iterations = 25;            // Newton iterations per increment (predictor included)
  double residual_tolerance = 1e-9;   // converged when |r_i| <= tol * max(|f_c|, force_floor): r_i the out-of-balance
                                      // force on the unknown dofs, f_c the reactions on the imposed dofs (N)
  double force_floor = 1e-12;         // N, the scale when the reactions are (nearly) zero
  int max_line_search_halvings = 10;  // step length down to 2^-halvings before the increment is declared failed
};

enum class HyperelasticStatus : std::uint8_t {
  kConverged = 0,  // the full load was reached and every increment converged
  kInverted,       // the load could not be reached without inverting a tet (J <= 0), even with the cuts allowed
  kNotConverged,   // Newton did not converge (or the tangent was singular), even with the cuts allowed
};
const char* to_string(HyperelasticStatus status);

/// One load increment as attempted (accepted or not).
struct HyperelasticStep {
  double load_factor = 0;         // target fraction s of the imposed displacements, 0 < s <= 1
  int iterations = 0;             // Newton iterations done (predictor included)
  std::vector<double> residuals;  // N, |r_i| after each iteration (residuals[k] after iteration k + 1)
  double force_scale = 0;         // N, max(|f_c|, force_floor) at the last state: the tolerance's scale
  bool converged = false;         // accepted; otherwise the increment was cut (see `failure`)
  std::string failure;            // why it was cut ("" when converged)
  int line_search_halvings = 0;   // total step halvings over the increment's corrections
  bool ldlt_fallback = false;     // the tangent was not positive definite at some iteration (LDL^T used)
  double min_jacobian = 1;        // smallest det F over the tets at the last state
  Eigen::MatrixX3d reaction;      // #I x 3, N: force on the organ at each imposed node (converged steps)
  Eigen::Vector3d total_reaction = Eigen::Vector3d::Zero();  // N, sum of reaction rows
};

struct HyperelasticSolution {
  HyperelasticStatus status = HyperelasticStatus::kConverged;
  std::string message;             // what went wrong and where (tet, J, load factor); "" when converged
  double load_factor = 0;          // load reached (1 when converged; the last converged increment otherwise)
  Eigen::MatrixX3d displacement;   // #V x 3, m, at load_factor: always finite (fixed dofs 0)
  std::vector<int> imposed_nodes;  // #I nodes with an imposed component, ascending
  Eigen::MatrixX3d reaction;       // #I x 3, N, at load_factor (0 on components left free)
  Eigen::Vector3d total_reaction = Eigen::Vector3d::Zero();  // N (the tool feels minus this)
  std::vector<HyperelasticStep> steps;                       // every increment attempted, in order
  int total_iterations = 0;                                  // Newton iterations over all steps
  int inverted_tet = -1;                                     // the tet that inverted (kInverted), else -1
  double min_jacobian = 1;                                   // smallest det F over the tets in the returned state

  bool converged() const { return status == HyperelasticStatus::kConverged; }
};

/// The unknown dofs (free and not imposed) of a solve with some imposed dofs and the part K_ii of a tangent that a
/// Newton iteration factors, in the model's pattern: shared by HyperelasticSolver::solve and the multirate tracker
/// (nonlinear/multirate.h). Allocates in make() and build() only.
struct ReducedSystem {
  std::vector<int> unknown;         // #dofs: index among the unknowns, or -1 (fixed or imposed)
  std::vector<int> imposed_dofs;    // global dofs with an imposed value, ascending
  Eigen::VectorXd target;           // #imposed: u* on those dofs, m
  Eigen::SparseMatrix<double> kii;  // unknowns x unknowns, values refreshed from the full K_T
  std::vector<int> kii_source;      // #kii nonzeros: value index in the full pattern
  int count = 0;                    // number of unknowns

  /// The unknowns of `model` when `imposed_dofs` (ascending) are imposed, and the pattern of K_ii (target sized, 0).
  static ReducedSystem make(const ElasticModel& model, const std::vector<int>& imposed_dofs);
  /// Pattern of K_ii from the full pattern (rows of each column stay sorted: the numbering is monotone).
  void build(const Eigen::SparseMatrix<double>& pattern);
  /// K_ii's values from a full tangent in the model's pattern.
  void refresh(const Eigen::SparseMatrix<double>& kt);
  /// r_i: the full vector restricted to the unknowns.
  Eigen::VectorXd restrict(const Eigen::VectorXd& full) const;
  /// |full| over the imposed dofs.
  double imposed_norm(const Eigen::VectorXd& full) const;
  /// rhs_i -= K_T(i, dof) dc for every unknown i (column `dof` of the symmetric tangent).
  void subtract_coupling(const Eigen::SparseMatrix<double>& kt, int dof, double dc, Eigen::VectorXd& rhs) const;
  /// full += alpha x on the unknowns (x indexed by unknown).
  void add_unknowns(const Eigen::VectorXd& x, double alpha, Eigen::VectorXd& full) const;
};

/// Solves K_ii x = b for every column of b: CHOLMOD, or Eigen's LDL^T when the tangent is not positive definite
/// (`ldlt_used` set then). False when singular or not finite.
bool solve_reduced_tangent(const Eigen::SparseMatrix<double>& kii, const Eigen::Ref<const Eigen::MatrixXd>& b,
                           Eigen::MatrixXd& x, bool& ldlt_used);

/// What one backtracking line search of a Newton correction did (HyperelasticSolver::line_search).
struct LineSearchOutcome {
  bool accepted = false;    // a step with sufficient decrease of |r_i| was taken
  bool any_valid = false;   // some trial step inverted no tet
  int halvings = 0;         // trials refused for too little decrease (not for inversion)
  double min_jacobian = 1;  // smallest det F at the accepted state
  int bad_tet = -1;         // the worst tet of the last inverted trial, else -1
};

/// The neo-Hookean organ: reads the mesh, material and fixed set of an ElasticModel (which must outlive it) and the
/// sparsity of its K. Construction throws surgsim::core::Error on a degenerate or inverted rest tet.
class HyperelasticSolver {
 public:
  explicit HyperelasticSolver(const ElasticModel& model, const HyperelasticOptions& options = HyperelasticOptions());

  /// Static equilibrium with u = u* on the imposed components, 0 on the fixed dofs, no other load. Input errors
  /// (see imposed_dof_values) and bad options throw surgsim::core::Error; a load that cannot be reached is a status,
  /// with the last converged state returned (never NaN).
  HyperelasticSolution solve(const std::vector<ImposedDisplacement>& imposed) const;

  /// Internal force f_int = dE/du (3N, N) and total strain energy (J) at displacement u (3N, m; dof 3 n + c).
  /// False when a tet is inverted or degenerate (det F <= 0): then f is unspecified and `worst_tet`, if given, names
  /// the tet with the smallest det F; `min_jacobian`, if given, receives that smallest det F either way.
  bool internal_force(const Eigen::VectorXd& u, Eigen::VectorXd& f, double* energy = nullptr,
                      double* min_jacobian = nullptr, int* worst_tet = nullptr) const;
  /// Consistent tangent K_T = d f_int / du (3N x 3N, N/m) at u, in the sparsity of the model's K (both triangles).
  /// False on an inverted tet (k then unspecified).
  bool tangent_stiffness(const Eigen::VectorXd& u, Eigen::SparseMatrix<double>& k) const;

  /// One correction's line search: tries v + alpha du_i (alpha = 1, 1/2, ... down to 2^-max_line_search_halvings)
  /// until |r_i| <= (1 - 1e-4 alpha) r, refusing any trial that inverts a tet. When accepted, v and f hold the new
  /// state and its internal force; otherwise they are unchanged. `trial`, `ft`: the caller's scratch.
  LineSearchOutcome line_search(const ReducedSystem& sys, const Eigen::VectorXd& du_i, double r, Eigen::VectorXd& v,
                                Eigen::VectorXd& f, Eigen::VectorXd& trial, Eigen::VectorXd& ft) const;

  const HyperelasticOptions& options() const { return options_; }
  const ElasticModel& model() const { return model_; }
  /// The base material's (a tet in a material region has its region's).
  const LameParameters& lame() const { return lame_; }

 private:
  const ElasticModel& model_;
  HyperelasticOptions options_;
  LameParameters lame_;
  std::vector<LameParameters> element_lame_;       // #T: each tet's own (its region's, else the base's)
  std::vector<Eigen::Matrix<double, 4, 3>> grad_;  // #T: reference gradients of the shape functions, 1/m
  std::vector<double> volume_;                     // #T: reference volumes, m^3
  std::vector<int> block_pos_;                     // #T x 16 x 3: value index of K(3 a, 3 b + k) in the pattern
};

}  // namespace surgsim::fem
