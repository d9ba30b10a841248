// Multirate non-linear contact (Cavusoglu & Tendick 2000, Astley & Hayward 1998, SOFA's running FEM with
// a precomputed correction): a slow thread runs the neo-Hookean organ (fem/hyperelastic.h) under the current
// contact constraints, a few Newton iterations per cycle from its last state, and publishes a local linear model
// about that state; the 1 kHz loop evaluates the model at the tool's current position.
//
// Slow side, NonlinearTracker::cycle(targets): the contact nodes' three components are imposed (components of the
// fixed set stay 0). From the current state u, each iteration assembles the tangent K_T(u), factors K_ii (CHOLMOD,
// the analysis kept while the contact set stays; LDL^T when not positive definite) and solves for [step | K_ic] at
// once. The step is a predictor (the contact dofs towards their targets by at most max_step per node, the unknowns by
// the linearized response, halved while it inverts a tet) when the state's relative residual is within
// move_tolerance, else a Newton correction with HyperelasticSolver's line search; then up to corrections_per_cycle
// modified Newton corrections on the same factor (cheap: an internal force and a one-column solve each). So every
// predictor starts near equilibrium, as a load step does, and a fast tool is followed over several cycles. A predictor
// whose state still has a relative residual above publish_tolerance after the corrections is taken back and the step
// limit halved (doubled back after an accepted step), and no state above it is published. From the same factorization:
//   S = K_cc - K_ci K_ii^-1 K_ic   (the contact stiffness of the tangent, the Schur complement, 3m x 3m, N/m)
//   f_c = f_int,c - (K_ii^-1 K_ic)^T r_i   (the reactions on the contact dofs, linearly corrected for the
//                                           remaining out-of-balance force r_i of the unknowns)
// S is that of the tangent before the iteration's step (stale by one step; exact once converged). The snapshot
// (u_c, f_c, S, the surface displacement) goes through a TripleBuffer (compliance/corotation.h).
// Allocates: the slow side only (a new contact set rebuilds the reduced system and the analysis).
//
// Fast side, snapshot_forces() / local_contact_forces(): lambda = f_c + S (u_c(now) - u_c(snapshot)) per node, no
// allocation, O(m^2).
// MultirateForce takes the newest snapshot and falls back to the linear precomputed model (Superposition::solve)
// when no valid snapshot covers the current contact set or the result is not finite.
#pragma once
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "fem/cholmod_solver.h"
#include "compliance/corotation.h"
#include "fem/hyperelastic.h"
#include "compliance/superposition.h"

namespace surgsim::nonlinear {

struct MultirateOptions {
  int iterations_per_cycle = 2;      // factorizations per slow cycle at most (>= 1)
  double residual_tolerance = 1e-9;  // converged when |r_i| <= tol * max(|f_c|, force_floor), as HyperelasticOptions
  double force_floor = 1e-12;        // N
  int max_predictor_halvings = 6;    // a predictor that inverts a tet is halved up to this many times
  int corrections_per_cycle = 10;    // modified Newton corrections after each step, on the same factor (>= 0)
  double move_tolerance = 1e-2;      // the contact dofs move towards new targets only from a state whose relative
                                     // residual is within this (else the iteration is a correction)
  double max_step = 0.005;           // m: the largest move of a contact node per predictor
  double publish_tolerance = 2e-2;   // a predictor whose state (after the corrections) has a larger relative
                                     // residual is taken back and the step limit halved (doubled back on success);
                                     // any state above it is not published (the fast side keeps the previous
                                     // snapshot): the linearly corrected f_c and S of a state far from equilibrium
                                     // can be wrong in sign (lift_90 in 0.5 s: 140-309 % force error)
  double max_extrapolation = 0.01;   // m: the fast side clamps |u_c(now) - u_c(snapshot)| of each node to this
  bool contact_stiffness = true;     // false: S left 0 and f_c uncorrected (a reference run that needs forces only)
};

/// The imposed displacements the fast side asks for (all three components of each node), fixed capacity.
struct ContactTargets {
  int count = 0;
  std::array<int, compliance::kMaxContacts> nodes{};
  std::array<Eigen::Vector3d, compliance::kMaxContacts> u{};  // m, from the rest position
};

/// One published state of the slow side. Preallocated (sized by NonlinearTracker); written in place.
struct TrackerSnapshot {
  bool valid = false;                                                // a finite state of this contact set
  std::uint64_t cycle = 0;                                           // the tracker's cycle that made it
  int count = 0;                                                     // contact nodes
  std::array<int, compliance::kMaxContacts> nodes{};                 // in the order of the targets
  std::array<Eigen::Vector3d, compliance::kMaxContacts> u{};         // m, the contact nodes' displacement in the state
  std::array<Eigen::Vector3d, compliance::kMaxContacts> reaction{};  // N, force on the organ at each node (f_c)
  Eigen::MatrixXd stiffness;  // (3 kMaxContacts)^2, N/m: S in the top-left 3 count block
  double residual = 0;        // |r_i| / max(|f_c|, floor) of the state
  bool converged = false;     // at the targets, residual within the tolerance, S exact
  Eigen::VectorXd surface;    // 3 x #surface nodes, m: the state's displacement there
};

/// What one slow cycle did.
struct TrackerCycle {
  int iterations = 0;          // factorizations
  bool converged = false;      // the published state is converged at the targets, S the tangent's there
  bool set_changed = false;    // the contact set differed from the previous cycle's (reduced system rebuilt)
  double residual = 0;         // relative, of the published state
  int predictor_halvings = 0;  // inversion cuts of the predictor
  int corrections = 0;         // modified Newton corrections accepted (on an iteration's factor)
  bool step_rejected = false;  // the predictor's state was above publish_tolerance: taken back, step limit halved
  bool ldlt_fallback = false;  // the tangent was not positive definite
  double assemble_ms = 0, factor_ms = 0, solve_ms = 0, total_ms = 0;  // wall clock: tangent + internal force,
                                                                      // analysis (a new set) + factor, solves
  bool published = false;  // a snapshot was published (not when the state's residual > publish_tolerance)
  std::string failure;     // "" or why the cycle did not step
};

class NonlinearTracker {
 public:
  /// `solver` (its model) must outlive the tracker. `surface_nodes`: the nodes whose displacement each snapshot
  /// carries (for drawing; the bench's visible nodes). Throws surgsim::core::Error on bad options.
  NonlinearTracker(const fem::HyperelasticSolver& solver, std::vector<int> surface_nodes,
                   const MultirateOptions& options = MultirateOptions());

  /// One slow cycle towards `targets` (see the file comment), then publishes a snapshot (unless the tangent was
  /// singular or inverted: the state is left as it was and `failure` says why; or the state's relative residual is
  /// above publish_tolerance: the previous snapshot stays the newest). Throws surgsim::core::Error for a node out
  /// of range, a repeated node or more than kMaxContacts.
  TrackerCycle cycle(const ContactTargets& targets);
  /// Back to rest (u = 0), nothing published.
  void reset();

  concurrency::TripleBuffer<TrackerSnapshot>& snapshots() { return snapshots_; }
  const Eigen::VectorXd& state() const { return u_; }  // 3N, m
  std::uint64_t cycles() const { return cycles_; }
  const MultirateOptions& options() const { return options_; }

 private:
  void publish(const ContactTargets& targets, const Eigen::MatrixXd& x, bool converged, double residual);

  const fem::HyperelasticSolver& solver_;
  const fem::ElasticModel& model_;
  std::vector<int> surface_nodes_;
  MultirateOptions options_;
  concurrency::TripleBuffer<TrackerSnapshot> snapshots_;
  std::uint64_t cycles_ = 0;
  Eigen::VectorXd u_, f_, v_, fv_, trial_, ft_, ri_, rhs_, dx_;
  Eigen::SparseMatrix<double> kt_;
  fem::ReducedSystem sys_;
  std::vector<int> dof_contact_;  // per imposed dof: 3 * (index in the targets) + component
  Eigen::MatrixXd b_, x_, s_;
  fem::CholmodSolver chol_;  // K_ii's factor: analysed when the contact set changes, refactored every iteration
  bool analysed_ = false;
  bool stuck_ = false;               // the last correction found no decrease: the next iteration moves regardless
  double step_cut_ = 1;              // fraction of max_step the predictor may take (halved on a rejected step)
  Eigen::VectorXd u_keep_, f_keep_;  // the state before the predictor (restored when its step is rejected)
};

/// The local model at contacts the snapshot may hold only in part (a patch whose edge nodes enter and leave), no
/// allocation: for each contact l (nodes[l], displacement[l] now) whose node the snapshot holds, lambda[l] = f_c + S du
/// over the contacts both hold (du = displacement - u_snapshot, clamped to `max_extrapolation` per node; the
/// snapshot's nodes no contact names contribute nothing) and held[l] = true; the other lambda[l] are left as they are,
/// held[l] = false. Returns the contacts matched: 0 (every held[l] false) for an invalid snapshot or a non-finite du
/// or result. `largest`: the largest |du| before the clamp (m).
int snapshot_forces(const TrackerSnapshot& snapshot, const int* nodes, const Eigen::Vector3d* displacement, int m,
                    double max_extrapolation, Eigen::Vector3d* lambda, bool* held, double& largest) noexcept;

/// The local model, no allocation: for each contact (node, u now) the snapshot's node, lambda = f_c + S du with du
/// clamped to `max_extrapolation` per node (snapshot_forces with every contact held); out.lambda (force on the organ),
/// out.tool_force = -sum, out.nodes and out.displacement filled as Superposition::solve does. False (out.count = 0)
/// when the snapshot is not valid, its node set differs from the contacts', or the result is not finite.
bool local_contact_forces(const TrackerSnapshot& snapshot, const compliance::Contact* contacts, int m,
                          double max_extrapolation, compliance::ContactSolution& out) noexcept;

/// Where a MultirateForce::evaluate result came from.
enum class MultirateSource : std::uint8_t { kNonlinear = 0, kLinearFallback };

/// The 1 kHz side: the newest snapshot of a tracker's buffer, or the linear model. One per haptic thread.
class MultirateForce {
 public:
  MultirateForce(concurrency::TripleBuffer<TrackerSnapshot>& snapshots, compliance::Superposition& linear,
                 double max_extrapolation)
      : snapshots_(snapshots), linear_(linear), max_extrapolation_(max_extrapolation) {}
  /// No allocation. Never returns a non-finite force: the linear model's result when the snapshot cannot be used.
  MultirateSource evaluate(const compliance::Contact* contacts, int m, compliance::ContactSolution& out) noexcept;
  std::uint64_t fallbacks() const { return fallbacks_; }

 private:
  concurrency::TripleBuffer<TrackerSnapshot>& snapshots_;
  compliance::Superposition& linear_;
  double max_extrapolation_;
  std::uint64_t fallbacks_ = 0;
};

}  // namespace surgsim::nonlinear
