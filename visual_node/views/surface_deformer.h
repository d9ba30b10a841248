// Deformation of the visible surface from received contact forces: u_n = sum_k G_nk lambda_k over the "visual"
// rows of the tensors (visible x surface; no interior rows are held), applied to a compacted copy of the boundary
// surface that the renderer draws. apply() allocates nothing.
#pragma once
#include <Eigen/Core>
#include <array>
#include <memory>
#include <vector>

#include "mesh/mesh.h"
#include "compliance/corotation.h"
#include "compliance/precompute.h"
#include "compliance/superposition.h"

namespace surgsim::nonlinear {
class NonlinearLaw;
}  // namespace surgsim::nonlinear

namespace surgsim {

class SurfaceDeformer {
 public:
  /// `tensors` (may be null: rest shape only) must hold the "visual" block and outlive this object.
  /// `law` (may be null: linear) applies P to the displacements orthogonal to the constraint direction.
  /// `deformation` kCorotational: the visual node recomputes the rotations itself from the
  /// displacements (nothing more is sent): per frame, kCorotationalPasses fixed-point passes of
  ///   u~_n = sum_l G(n, k_l) R_l^T lambda_l,  then R_n of every visible node from u~ (compliance/corotation.h),
  /// and the drawn u_n = R_n u~_n with the last rotations;
  /// warm-started from the previous frame's rotations; the law's P comes after, on the warped u.
  SurfaceDeformer(const mesh::TetMesh& mesh, const mesh::SurfaceMesh& surface, const compliance::Tensors* tensors,
                  const nonlinear::NonlinearLaw* law = nullptr,
                  compliance::LiverDeformation deformation = compliance::LiverDeformation::kLinear);
  static constexpr int kCorotationalPasses = 2;

  /// Deforms for forces lambda (N) on m contact nodes (mesh indices). m = 0 restores the rest shape. On a bad
  /// input (unknown node, non-finite lambda) the previous shape is kept and the status says why. `direction`
  /// (unit; the ContactFrame's mean imposed displacement) is the axis of the non-linear law; zero skips it.
  compliance::ContactStatus apply(const int* nodes, const Eigen::Vector3d* lambda, int m,
                                  const Eigen::Vector3d& direction = Eigen::Vector3d::Zero()) noexcept;
  /// Several instruments: contact l belongs to instrument instrument[l], whose mean imposed displacement
  /// direction is directions[instrument[l]] (`instruments` of them). The displacements are the same linear sum
  /// u = sum_l G(., k_l) lambda_l; the non-linear law bends each instrument's share u_i (its own contacts) about its
  /// own direction before the shares are added. Contacts naming an instrument outside 0..instruments-1 or one with
  /// a zero direction are superposed linearly. One instrument: the same as apply(nodes, lambda, m, direction).
  compliance::ContactStatus apply(const int* nodes, const Eigen::Vector3d* lambda, const int* instrument, int m,
                                  const Eigen::Vector3d* directions, int instruments) noexcept;

  /// The shape itself (liver.deformation multirate: the haptic node's tracker publishes it as BodyState):
  /// `xyz` holds x, y, z (m) of every visible vertex in SurfaceMesh node order (the order of visible_nodes()),
  /// `count` of them; the embedded surface follows. False, and the previous shape kept, when `count` is not the
  /// visible vertex count or a value is not finite. No allocation.
  bool set_positions(const double* xyz, int count) noexcept;
  /// A shape carried to where the contacts are now (multirate: the tracker's last shape `xyz`, as set_positions, and
  /// the contact nodes' imposed displacements `contacts` of this frame): the linear response that takes each contact
  /// node from its place in `xyz` to rest + its displacement, lambda = G_CC^-1 (u* - u_xyz), added to the whole
  /// shape, so the contact nodes land exactly where the tool holds them and the rest follows linearly between two
  /// tracker states. m = 0 is set_positions. kOk, or why not (then the previous shape is kept). No allocation.
  compliance::ContactStatus carry_positions(const double* xyz, int count, const compliance::Contact* contacts,
                                            int m) noexcept;

  /// Embeds a finer visual surface: each of its vertices is tied to the closest point of the mechanical boundary
  /// (triangle, barycentric coordinates, offset along the triangle's normal) and follows it. Only boundary rows are
  /// used, so the visual node still holds no interior rows. Throws surgsim::core::Error naming the file and the first
  /// vertex further than `max_distance` (m) from the boundary.
  void embed(const mesh::TriSurface& fine, const mesh::TetMesh& mesh, const mesh::SurfaceMesh& surface,
             double max_distance);
  bool embedded() const { return fine_tris_.rows() > 0; }
  /// What the renderer draws: the embedded surface when there is one, else the boundary.
  const Eigen::MatrixX3f& drawn_positions() const { return embedded() ? fine_positions_ : positions_; }
  const Eigen::MatrixX3i& drawn_tris() const { return embedded() ? fine_tris_ : tris_; }

  const Eigen::MatrixX3f& positions() const { return positions_; }  // #visible x 3, m, deformed
  const Eigen::MatrixX3f& rest() const { return rest_; }            // #visible x 3, m
  const Eigen::MatrixX3i& tris() const { return tris_; }            // #F x 3 into positions
  const std::vector<int>& visible_nodes() const { return visible_nodes_; }  // vertex v -> mesh node
  /// Vertex of a mesh node, or -1 when the node is not visible or not a node of this mesh (a bad contact frame).
  int vertex_of(int node) const {
    return node >= 0 && static_cast<std::size_t>(node) < vertex_of_node_.size()
               ? vertex_of_node_[static_cast<std::size_t>(node)] : -1;
  }
  /// Largest displacement of any visible vertex in the current shape (m).
  double max_displacement() const { return max_displacement_; }
  bool has_tensors() const { return superposition_ != nullptr; }
  /// The rotations in use (corotational; null otherwise).
  const compliance::NodeRotations* rotations() const { return rotations_.get(); }

 private:
  std::vector<int> visible_nodes_;
  std::vector<int> vertex_of_node_;
  std::vector<int> block_row_;
  Eigen::MatrixX3i tris_;
  Eigen::MatrixX3f rest_;
  Eigen::MatrixX3f positions_;
  std::unique_ptr<compliance::Superposition> superposition_;
  const nonlinear::NonlinearLaw* law_ = nullptr;
  // Embedded surface: per fine vertex, the boundary triangle's vertices, barycentrics and normal offset (m).
  Eigen::MatrixX3i fine_tris_;
  Eigen::MatrixX3i fine_anchor_;
  Eigen::MatrixX3f fine_bary_;
  Eigen::VectorXf fine_offset_;
  Eigen::MatrixX3f fine_positions_;
  void update_fine() noexcept;
  /// The shape from the displacements u (3 per "visual" row).
  void set_shape(const Eigen::VectorXd& u) noexcept;
  Eigen::VectorXd u_;
  Eigen::VectorXd u_sum_;  // apply() with several instruments: the sum of their shares
  // carry_positions(): the contacts' displacements from the given shape and their linear solution.
  std::array<compliance::Contact, compliance::kMaxContacts> carry_{};
  compliance::ContactSolution carry_solution_;
  // One instrument's contacts, gathered (kMaxContacts each).
  std::vector<int> group_nodes_;
  std::vector<Eigen::Vector3d> group_lambda_;
  double max_displacement_ = 0;
  // --- corotational ---
  /// u (3 per visual row) for forces lambda on m contact nodes: linear, or warped by the current rotations.
  compliance::ContactStatus displace(const int* nodes, const Eigen::Vector3d* lambda, int m, Eigen::VectorXd& u,
                                     bool rotate_rows = true) noexcept;
  /// The rotations of every visible node from the contacts (kCorotationalPasses passes); u_ holds the last pass's u.
  compliance::ContactStatus update_rotations(const int* nodes, const Eigen::Vector3d* lambda, int m) noexcept;
  std::unique_ptr<compliance::NodeRotations> rotations_;
  std::vector<Eigen::Vector3d> rest_lambda_;  // kMaxContacts: R_l^T lambda_l
};

}  // namespace surgsim
