// Superposition of precomputed elementary responses (docs/DESIGN.md, section 'Liver: precomputed linear elasticity'):
// for m contacts C = {k_1..k_m} with imposed displacements u*, lambda_C = G_CC^-1 u* (3m x 3m), the displacement of
// any node n is u_n = sum_l G(n, k_l) lambda_l and the force the tool feels is -sum_l lambda_l. Exact linear
// elasticity up to the storage precision.
//
// Callers:
//   haptic loop (>= 300 Hz): Superposition on the "haptic" block; solve() for the contacts, then displacement() of
//     a few candidate nodes. Both are noexcept and allocate nothing: the workspace is sized at construction for a
//     fixed contact capacity; problems come back as a ContactStatus, never as an exception.
//   visual node (>= 50 Hz): Superposition on the "visual" block; displacements() of every visible node from the
//     received (node, lambda) pairs, into a caller-owned buffer. Also allocation-free.
//   tests / paper comparison: PaperTensors, the paper's own form (T^u, T^f, mutual influence M, corrected
//     constraints u~); allocates, not for the loops.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "compliance/precompute.h"

namespace surgsim::compliance {

/// Most simultaneous contact nodes a Superposition can take (ToolSpec::contact_capacity is 1..64).
constexpr int kMaxContacts = 64;

enum class ContactStatus : std::uint8_t {
  kOk = 0,
  kOverCapacity,    // more distinct contact nodes than the capacity
  kInvalidNode,     // node index outside the mesh
  kFixedNode,       // contact on a fixed node: refused
  kNotContactable,  // node has no precomputed column (interior node)
  kNotInBlock,      // node is not a row of the block in use
  kNonFinite,       // NaN or infinite displacement / lambda in the input
  kNearSingular,    // G_CC is (numerically) singular: rcond below the threshold
};
const char* to_string(ContactStatus status);

/// Whether `node` can carry a contact on `block`: kOk, or why not (out of range, fixed, no precomputed column, not a
/// row of the block). No allocation; Superposition::solve and PatchSolver::prepare refuse nodes with it.
ContactStatus contact_node_status(const Tensors& tensors, const TensorBlock& block, int node) noexcept;

/// One imposed contact: node k and its displacement u*_k (m).
struct Contact {
  int node = -1;
  Eigen::Vector3d displacement = Eigen::Vector3d::Zero();  // m
};

/// One known force on the organ: node k and the force on it (N).
struct Load {
  int node = -1;
  Eigen::Vector3d force = Eigen::Vector3d::Zero();  // N
};

/// Result of Superposition::solve(). Fixed capacity, no heap: lives in the caller's preallocated state.
struct ContactSolution {
  ContactStatus status = ContactStatus::kOk;
  int count = 0;                                           // distinct contact nodes after merging (0 on error)
  std::array<int, kMaxContacts> nodes{};                   // contact node indices, in first-seen input order
  std::array<Eigen::Vector3d, kMaxContacts> displacement;  // m, the imposed u* per node (mean of merged requests)
  std::array<Eigen::Vector3d, kMaxContacts> lambda;        // N, force on the organ at nodes[l]
  std::array<Eigen::Vector3d, kMaxContacts> corrected;     // m, the paper's corrected constraint u~_l = G_kk lambda_l
  Eigen::Vector3d tool_force = Eigen::Vector3d::Zero();    // N, force on the tool = -sum lambda (0 on error)
  int merged_duplicates = 0;    // input contacts folded into an earlier one with the same node
  double duplicate_spread = 0;  // m, largest distance between a merged request and the mean it was merged into
  int bad_input = -1;           // index of the offending input contact when status != kOk (else -1)
  // Reciprocal condition number of G_CC in the 1-norm, 1 / (||G_CC||_1 est||G_CC^-1||_1), estimated from its
  // Cholesky factor as LAPACK's dpocon (Hager / Higham, a few O(m^2) solves, no allocation). The estimate of
  // ||G_CC^-1||_1 is a lower bound, so rcond is never below the exact value and in practice within a factor of 3
  // of it. 1 with no contact, 0 when the factorization fails.
  double rcond = 1;
};

/// Units: displacements in m, forces in N, G in m/N. solve() writes this object's workspace: use one Superposition
/// per thread; the const members may be called from any thread. The Tensors must outlive it and stay in place.
class Superposition {
 public:
  /// Init phase (allocates): binds to `tensors` (must outlive this object) and its block `block_name`, with a
  /// workspace for `capacity` (1..kMaxContacts) contacts. G_CC is reported near-singular when rcond <
  /// `near_singular_rcond`. Throws surgsim::core::Error for an unknown block or a bad capacity.
  Superposition(const Tensors& tensors, const std::string& block_name, int capacity = kMaxContacts,
                double near_singular_rcond = 1e-12);

  int capacity() const { return capacity_; }
  const Tensors& tensors() const { return tensors_; }
  const TensorBlock& block() const { return block_; }

  /// Run phase, no allocation. Merges duplicate nodes (mean displacement), refuses fixed, interior or out-of-range
  /// nodes and non-finite input, builds G_CC (3m x 3m) and solves lambda = G_CC^-1 u*. `contacts`: m entries (m may
  /// exceed the capacity if duplicates bring it down). Contact nodes must be rows of this block (true for "haptic"
  /// and "visual"). On any status but kOk the solution has count 0 and zero force.
  ContactStatus solve(const Contact* contacts, int m, ContactSolution& out) noexcept;
  /// The same with known forces on the organ besides the contacts' (another organ resting on it: the bowel on the
  /// liver): `loads[0..load_count)` at their nodes (each with a precomputed column; a node may repeat). The contacts
  /// still reach their imposed displacements: lambda = G_CC^-1 (u* - G_CB f_B), and the organ's displacement is then
  /// G lambda + G f_B (displacement() of the contacts and of the loads). The tool's force stays -sum lambda. A load on
  /// a node without a column or a non-finite load is refused (kNotContactable / kNonFinite; bad_input = m + its index).
  ContactStatus solve(const Contact* contacts, int m, const Load* loads, int load_count, ContactSolution& out) noexcept;

  /// Run phase, no allocation: u (m) of `node` (a row of this block, or a fully fixed node: u = 0) under the solved
  /// contacts. False when `node` is neither or `solution` is not ok.
  bool displacement(int node, const ContactSolution& solution, Eigen::Vector3d& u) const noexcept;

  /// Run phase, no allocation: u (m) of `node` (a row of this block, or a fully fixed node: u = 0) for forces lambda
  /// (N) on m contact nodes.
  ContactStatus displacement(int node, const int* contact_nodes, const Eigen::Vector3d* lambda, int m,
                             Eigen::Vector3d& u) const noexcept;

  /// Run phase, no allocation: displacements (m) of every row node of this block for forces lambda (N) on m contact
  /// nodes. `out` has 3R entries, (x, y, z) of block().row_nodes[r] at 3r..3r+2; it is overwritten. Returns kOk, or
  /// the first problem (then `out` is zero): a node without a column, a non-finite lambda, a size mismatch
  /// (kInvalidNode).
  ContactStatus displacements(const int* contact_nodes, const Eigen::Vector3d* lambda, int m,
                              Eigen::Ref<Eigen::VectorXd> out) const noexcept;

  /// Run phase, no allocation: the forces lambda_l = (G_kk)^-1 u~_l (N) from corrected constraints u~ (m), for a
  /// receiver of (node, u~) pairs. lambda must hold m entries.
  ContactStatus lambda_from_corrected(const int* contact_nodes, const Eigen::Vector3d* corrected, int m,
                                      Eigen::Vector3d* lambda) const noexcept;

 private:
  const Tensors& tensors_;
  const TensorBlock& block_;
  int capacity_;
  double near_singular_rcond_;
  Eigen::MatrixXd gcc_;  // 3 capacity x 3 capacity: G_CC, then its Cholesky factor in place
  Eigen::VectorXd rhs_;  // 3 capacity
  std::array<int, kMaxContacts> merged_count_{};
};

/// The paper's form (Cotin 1998, section 3.3), from the same tensors: T^f_k = (G_kk)^-1 (N/m) for each contact node,
/// T^u_nk = G_nk (G_kk)^-1 (dimensionless) for each row node n of a block. For contacts C the mutual-influence matrix
/// M (M_lj = T^u_{k_l k_j}, identity blocks on the diagonal) gives the corrected constraints M u~ = u*; then
/// u_n = sum_l T^u_{n k_l} u~_l and lambda_l = T^f_{k_l} u~_l. Allocates: for validation, not for the loops.
class PaperTensors {
 public:
  struct Solution {
    ContactStatus status = ContactStatus::kOk;
    std::vector<int> nodes;                                // merged contact nodes (same order as Superposition::solve)
    std::vector<Eigen::Vector3d> displacement;             // m, u*
    std::vector<Eigen::Vector3d> corrected;                // m, u~
    std::vector<Eigen::Vector3d> lambda;                   // N, T^f u~
    Eigen::Vector3d tool_force = Eigen::Vector3d::Zero();  // N
  };

  /// Builds T^u for the rows of `block_name` and T^f for every contact node (which must all be rows of that block).
  /// Throws surgsim::core::Error otherwise.
  PaperTensors(const Tensors& tensors, const std::string& block_name);

  const Eigen::MatrixXd& tu() const { return tu_; }  // 3R x 3S
  const Eigen::Matrix3d& tf(int column) const { return tf_[static_cast<std::size_t>(column)]; }

  Solution solve(const std::vector<Contact>& contacts) const;
  /// u (3R, as Superposition::displacements) from corrected constraints u~ on contact nodes.
  Eigen::VectorXd displacements(const std::vector<int>& contact_nodes,
                                const std::vector<Eigen::Vector3d>& corrected) const;

 private:
  const Tensors& tensors_;
  const TensorBlock& block_;
  Eigen::MatrixXd tu_;
  std::vector<Eigen::Matrix3d> tf_;
};

}  // namespace surgsim::compliance
