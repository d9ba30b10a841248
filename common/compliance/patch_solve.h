// Patch constraints through the precomputed tensors: a tool point of finite radius touches the
// organ over a patch of surface nodes with smooth weights w_i (sum 1); its contact is one or more SCALAR constraints
// on the weighted mean displacement of the patch,  d_k^T sum_i w_i u_i = b_k  (d_k a unit direction: the patch
// normal for a frictionless contact, three orthonormal directions for a sticking contact or a grasp). With
// C = [c_1 .. c_m], c_k = (w_i d_k) over the patch nodes, the multipliers solve the m x m system
//   (C^T G C) mu = b,   and the force on node i is  lambda_i = sum_k w_ki d_k mu_k,
// the same dense solve as Superposition (lambda = G_CC^-1 u*) but on scalar rows: G_CC of the patch nodes is
// contracted with the weights and directions. Exact linear elasticity for that constraint (compare
// tests/common/compliance/patch_solve_test.cpp against a direct solve of K u = C lambda).
//
// Phases: the constructor allocates (workspace for kMaxContacts union nodes, kMaxPatches patches, kMaxPatchRows
// rows); prepare(), factor(), solve(), node_forces() allocate nothing and never throw.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "compliance/corotation.h"
#include "compliance/superposition.h"

namespace surgsim::compliance {

constexpr int kMaxPatches = 128;                // patches per solve (one per tool point: 4 instruments x 32)
constexpr int kMaxPatchRows = 3 * kMaxPatches;  // scalar rows per solve
constexpr int kMaxPatchEntries = kMaxPatches * kMaxContacts;  // (patch, node) weights per solve

/// The constraints of one solve. Plain data, fixed capacity: lives in the caller's preallocated state.
struct PatchConstraints {
  int node_count = 0;                     // distinct nodes (the union of the patches)
  std::array<int, kMaxContacts> nodes{};  // mesh node indices
  int patch_count = 0;
  std::array<int, kMaxPatches + 1> patch_start{};  // entries of patch p: [patch_start[p], patch_start[p + 1])
  std::array<int, kMaxPatchEntries> entry_node{};  // index into nodes
  std::array<double, kMaxPatchEntries> entry_weight{};
  int row_count = 0;
  std::array<int, kMaxPatchRows> row_patch{};
  std::array<Eigen::Vector3d, kMaxPatchRows> row_direction;  // unit
  // Optional per patch: a compliance in series with the patch's mean displacement (m/N), added to M_pp as
  // near_normal[p] a a^T + near_tangent[p] (I - a a^T) with a = near_axis[p] (unit). The contact uses it for the
  // instrument's near field that the mesh cannot resolve (contact/near_field.h). 0: none.
  std::array<double, kMaxPatches> near_normal{};
  std::array<double, kMaxPatches> near_tangent{};
  std::array<Eigen::Vector3d, kMaxPatches> near_axis;

  void clear() {
    node_count = patch_count = row_count = 0;
    patch_start[0] = 0;
    near_normal.fill(0);
    near_tangent.fill(0);
  }
};

class PatchSolver {
 public:
  /// Init (allocates). Throws surgsim::core::Error for an unknown block.
  PatchSolver(const Tensors& tensors, const std::string& block_name);

  /// Run phase: reads G of the union nodes (symmetrized, 3x3 blocks) and the patch compliances
  /// M_pq = sum_i sum_j w_pi w_qj G_ij (m/N). G is read only for the nodes that were not in the previous prepare()'s
  /// union, in any order (a held contact reads nothing again; a sliding one reads the blocks of the nodes its
  /// footprint gained, against the union): each node keeps a storage slot while it stays in the union. The values are
  /// those a full read gives, bit for bit. Refuses fixed, interior, non-row or out-of-range nodes, non-finite or
  /// negative weights (the status; nothing is usable then).
  ContactStatus prepare(const PatchConstraints& c) noexcept { return prepare(c, nullptr); }
  /// Corotational (compliance/corotation.h): as prepare(c), then every block is warped, W_ab = R_a G_ab R_b^T
  /// with rotations[u] the rotation of union node u (null: G unwarped, as prepare(c)). Everything after it
  /// (compliance(), factor(), solve(), node_forces(), union_displacement(), g()) is in the world frame: the row
  /// directions and node forces are world vectors, the displacements the rotated response. `halves` other than
  /// kBoth is a test seam (the one-half mistakes). The raw G stays cached for the next prepare.
  ContactStatus prepare(const PatchConstraints& c, const Eigen::Matrix3d* rotations,
                        RotationHalves halves = RotationHalves::kBoth) noexcept;
  /// Run phase, after prepare(): A = [d_k^T M_{p(k) p(l)} d_l] and its Cholesky factor, for the rows whose `enabled`
  /// entry is non-zero (null: all). A row that depends on earlier ones (pivot below 1e-9 of its diagonal) gives
  /// kNearSingular and its index in dependent_row().
  ContactStatus factor(const PatchConstraints& c, const unsigned char* enabled = nullptr) noexcept;
  /// Run phase, after factor(): mu = A^-1 b over the enabled rows (b, mu: row_count entries; disabled rows get 0).
  void solve(const double* b, double* mu) const noexcept;
  /// lambda_u = sum_k w_{p(k) u} d_k mu_k for every union node (N, force on the organ).
  void node_forces(const PatchConstraints& c, const double* mu, Eigen::Vector3d* lambda) const noexcept;
  /// Displacement (m) of union node u under node forces lambda (union order), from the G read by prepare().
  Eigen::Vector3d union_displacement(int u, const Eigen::Vector3d* lambda, int n) const noexcept;
  /// The displacements of union nodes 0..n-1 at once (out[u] = union_displacement(u, lambda, n) up to rounding), in
  /// one dense product over the storage slots.
  void union_displacements(const Eigen::Vector3d* lambda, int n, Eigen::Vector3d* out) noexcept;
  /// Patch compliance M_pq (m/N) from the last prepare().
  Eigen::Matrix3d compliance(int p, int q) const noexcept { return m_[static_cast<std::size_t>(p * kMaxPatches + q)]; }
  /// G block (m/N) between union nodes a and b from the last prepare().
  Eigen::Matrix3d g(int a, int b) const noexcept;
  int dependent_row() const { return dependent_row_; }
  const Tensors& tensors() const { return tensors_; }

 private:
  /// Block (a, b) of the blocks in use, by union index.
  auto blk(int a, int b) const noexcept {
    return w_->block<3, 3>(3 * slot_[static_cast<std::size_t>(a)], 3 * slot_[static_cast<std::size_t>(b)]);
  }

  const Tensors& tensors_;
  const TensorBlock& block_;
  // G and its warp are stored by slot, not by union index: a node keeps its slot while it stays in the union, so its
  // blocks with the other staying nodes are not read again when the union's order changes.
  Eigen::MatrixXd guu_;               // 3 kMaxContacts square, by slot
  Eigen::MatrixXd wuu_;               // 3 kMaxContacts square, by slot: the warped blocks (corotational prepare)
  const Eigen::MatrixXd* w_ = &guu_;  // the blocks in use: guu_ or wuu_
  std::array<int, kMaxContacts> slot_{};                  // slot of each union node of the last prepare
  std::array<int, kMaxContacts> slot_node_{};             // mesh node whose G the slot holds, or -1
  std::array<std::uint32_t, kMaxContacts> slot_stamp_{};  // the prepare that last used the slot
  std::array<unsigned char, kMaxContacts> fresh_{};       // union node u's slot was just assigned (its blocks to read)
  std::vector<int> slot_of_node_;                         // per mesh node: its slot, or -1
  std::uint32_t stamp_ = 0;
  int slot_end_ = 0;                             // 1 + the highest slot of the last union
  Eigen::VectorXd slot_in_, slot_out_;           // 3 kMaxContacts: union_displacements' product by slot
  std::array<Eigen::Matrix3d, kMaxContacts> h_;  // H_q at each union node (one patch q at a time)
  std::array<Eigen::Matrix3d, kMaxPatches * kMaxPatches> m_;
  Eigen::MatrixXd a_;                       // kMaxPatchRows square: A, then its factor
  std::array<int, kMaxPatchRows> order_{};  // enabled rows in order
  int enabled_count_ = 0;
  int row_count_ = 0;
  int dependent_row_ = -1;
  int prepared_nodes_ = 0;
  std::uint64_t g_blocks_read_ = 0;  // 3x3 blocks of G read from the tensors since construction

 public:
  /// 3x3 blocks of G read from the tensors since construction (the others were reused).
  std::uint64_t g_blocks_read() const { return g_blocks_read_; }
};

}  // namespace surgsim::compliance
