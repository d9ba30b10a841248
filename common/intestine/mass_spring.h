// Damped mass-spring system (docs/DESIGN.md, section 'Intestine: mass-spring + stochastic collisions'): structural,
// shear and bending springs, gravity, viscous drag and penalty contacts (the probe), integrated at the haptic step.
//
// Two integrators:
//   kImplicitEuler   linearized backward Euler (Baraff & Witkin 1998): one Newton step,
//                    (M - h D - h^2 K) dv = h (f + h K v),  v += dv,  x += h v.
//                    K is the spring Jacobian with the transverse term clamped at zero under compression, D the
//                    damping Jacobian, so the matrix is symmetric positive definite. It is solved exactly by a
//                    Cholesky factorization in 3 x 3 node blocks on an envelope (skyline) fixed at construction: node
//                    slot s couples to slots first(s)..s, where first(s) is the lowest slot a spring joins to s or to
//                    a later slot; the fill stays inside it. The node ordering keeps it narrow (the intestine's
//                    column-by-column order: 4 to 6 nodes, against a band of 6 everywhere, 35 % fewer operations).
//                    Each step assembles the matrix straight into the factor's storage (offsets fixed at
//                    construction), factors it with the forward substitution fused in, and solves back. The cost
//                    does not grow with the stiffness: stable at 1 ms for springs of 1e2..1e6 N/m.
//   kSymplecticEuler explicit (semi-implicit) Euler, v += h M^-1 f, x += h v. Kept only to show where an explicit
//                    step fails: it is stable only for h < 2 / omega_max, omega_max ~ sqrt(sum of a node's stiffnesses
//                    / its mass): on the intestine's 4 g mesentery nodes about 1.4 ms at 1e3 N/m, 0.45 ms at 1e4 and
//                    0.14 ms at 1e5, so at the 1 ms haptic step it blows up from 1e4 N/m on (intestine_bench).
//
// Phases: MassSpring is immutable after construction (topology, rest lengths, masses, envelope layout);
// MassSpringWorkspace holds everything a step writes and is sized at construction, so integrate() allocates nothing.
// Units: m, kg, s, N. Positions and velocities are 3 x N column-major matrices: (x, y, z) of node n at 3n..3n+2.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

namespace surgsim::intestine {

enum class SpringKind : std::uint8_t { kStructural = 0, kShear = 1, kBending = 2 };

/// One damped spring between nodes i and j: f_i = (k (l - rest) + c (v_j - v_i).u) u, u = (x_j - x_i) / l.
struct Spring {
  int i = 0, j = 0;
  double rest = 0;       // m
  double stiffness = 0;  // N/m
  double damping = 0;    // N s/m, along the spring
  SpringKind kind = SpringKind::kStructural;
};

enum class Integrator : std::uint8_t { kImplicitEuler = 0, kSymplecticEuler = 1 };
const char* to_string(Integrator integrator);

/// A penalty contact on up to 3 nodes (a point of a segment or triangle): the point p = sum w_k x_k is pushed along
/// `normal` with force stiffness * depth (N), shared as w_k * force. The implicit integrator linearizes
/// depth(x) = depth0 - normal . (p(x) - p(x0)), which keeps a stiff probe stable.
struct PenaltyContact {
  int count = 0;                                   // 1..3 nodes
  std::array<int, 3> nodes{{-1, -1, -1}};
  std::array<double, 3> weights{{0, 0, 0}};        // barycentric, sum 1
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, direction of the force on the body
  double depth = 0;                                // m, > 0
  double stiffness = 0;                            // N/m
};

class MassSpringWorkspace;

/// Where a spring's three blocks sit in the factor's storage: offsets of the (3 x 3, column-major) blocks and their
/// column strides; -1 for a block of a fixed node.
struct SpringBlocks {
  int spring = 0;                 // index into MassSpring::springs()
  int diag_i = -1, stride_i = 0;  // block (slot i, slot i)
  int diag_j = -1, stride_j = 0;  // block (slot j, slot j)
  int off = -1, stride = 0;       // block (larger slot, smaller slot)
};

enum class IntegrateStatus : std::uint8_t {
  kOk = 0,
  kNonFinite,        // a non-finite force, velocity or position appeared: the state was restored
  kNotPositive,      // the implicit matrix lost positive definiteness (bad parameters): the state was restored
};
const char* to_string(IntegrateStatus status);

/// The immutable system. `order` gives each node's slot in the factorization (fixed nodes are skipped); the
/// envelope of the implicit matrix follows from it and the springs.
class MassSpring {
 public:
  /// Init phase (allocates, throws surgsim::core::Error on bad input): `rest` 3 x N (m), `mass` N (kg, > 0 for free
  /// nodes), `fixed` N flags, `springs` (rest lengths taken from the Spring entries), `gravity` (m/s^2), `drag` (1/s,
  /// force -drag m v). `order`: N entries, a permutation of the free nodes into 0..F-1 (fixed nodes: any value,
  /// ignored); empty = natural order of the free nodes.
  MassSpring(Eigen::Matrix3Xd rest, std::vector<double> mass, std::vector<std::uint8_t> fixed,
             std::vector<Spring> springs, const Eigen::Vector3d& gravity, double drag, std::vector<int> order = {});

  int node_count() const { return static_cast<int>(rest_.cols()); }
  int free_count() const { return free_count_; }
  const Eigen::Matrix3Xd& rest() const { return rest_; }
  const std::vector<double>& mass() const { return mass_; }
  const std::vector<double>& inverse_mass() const { return inv_mass_; }  // 0 for fixed nodes
  bool fixed(int n) const { return fixed_[static_cast<std::size_t>(n)] != 0; }
  const std::vector<Spring>& springs() const { return springs_; }
  const Eigen::Vector3d& gravity() const { return gravity_; }
  double drag() const { return drag_; }
  /// Slot of node n in the factorization (-1 for a fixed node) and the node in slot s.
  int slot(int n) const { return slot_[static_cast<std::size_t>(n)]; }
  int node_of_slot(int s) const { return node_of_slot_[static_cast<std::size_t>(s)]; }
  /// Half bandwidth of the implicit matrix in nodes (the widest spring between two free slots) and in scalars.
  int node_band() const { return node_band_; }
  int scalar_band() const { return 3 * node_band_ + 2; }
  /// Envelope: row s of the factor has node blocks first_slot(s)..s (first_slot non-decreasing in s); column s has
  /// rows s..last_slot(s), stored as a panel of 3 (last_slot(s) - s + 1) rows x 3 columns at panel_offset(s).
  int first_slot(int s) const { return first_slot_[static_cast<std::size_t>(s)]; }
  int last_slot(int s) const { return last_slot_[static_cast<std::size_t>(s)]; }
  std::size_t panel_offset(int s) const { return panel_offset_[static_cast<std::size_t>(s)]; }
  /// Doubles of the factor's storage (sum of the panels).
  std::size_t factor_size() const { return panel_offset_.back(); }
  /// Every spring's blocks, in assembly order (by the smaller slot: the step writes the storage front to back).
  const std::vector<SpringBlocks>& spring_blocks() const { return spring_blocks_; }

  /// Spring + gravity potential energy (J) of positions x (3 x N), gravity measured from the origin.
  double potential_energy(const Eigen::Matrix3Xd& x) const;
  /// Kinetic energy (J).
  double kinetic_energy(const Eigen::Matrix3Xd& v) const;

 private:
  Eigen::Matrix3Xd rest_;
  std::vector<double> mass_;
  std::vector<double> inv_mass_;
  std::vector<std::uint8_t> fixed_;
  std::vector<Spring> springs_;
  Eigen::Vector3d gravity_;
  double drag_ = 0;
  std::vector<int> slot_;
  std::vector<int> node_of_slot_;
  std::vector<int> first_slot_, last_slot_;
  std::vector<std::size_t> panel_offset_;  // free_count + 1 entries
  std::vector<SpringBlocks> spring_blocks_;
  int free_count_ = 0;
  int node_band_ = 0;
};

/// Everything integrate() writes besides x and v, sized at construction for one MassSpring.
class MassSpringWorkspace {
 public:
  explicit MassSpringWorkspace(const MassSpring& system);

  /// Smallest Cholesky pivot of the last implicit step, sqrt(kg): a conditioning indicator (> 0 when the step solved).
  double min_pivot() const { return min_pivot_; }
  /// Largest Cholesky pivot of the last implicit step, sqrt(kg). (max_pivot / min_pivot)^2 estimates the condition
  /// number of the implicit matrix M - h D - h^2 K (a lower bound, as CHOLMOD's rcond).
  double max_pivot() const { return max_pivot_; }

 private:
  friend IntegrateStatus integrate(const MassSpring&, Integrator, const PenaltyContact*, int, double,
                                   Eigen::Matrix3Xd&, Eigen::Matrix3Xd&, MassSpringWorkspace&) noexcept;
  std::vector<double> factor_;  // the panels (MassSpring::panel_offset): the matrix, then its Cholesky factor L
  std::vector<double> rhs_;     // 3 free nodes, slot order: the right-hand side, then the solution dv
  Eigen::Matrix3Xd force_;      // 3 x N: f (explicit), f + h K v (implicit)
  Eigen::Matrix3Xd x0_, v0_;    // backup for the non-finite guard of the explicit step
  double min_pivot_ = 0;
  double max_pivot_ = 0;
};

/// Run phase, no allocation: advances (x, v) by dt (s) with `contacts` penalty contacts (may be null when count is
/// 0). Fixed nodes keep their positions and zero velocity. On any non-finite value or a failed factorization x and v
/// are restored to their values on entry and the status says why.
IntegrateStatus integrate(const MassSpring& system, Integrator integrator, const PenaltyContact* contacts, int count,
                          double dt, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, MassSpringWorkspace& work) noexcept;

}  // namespace surgsim::intestine
