#include "surface_deformer.h"

#include <cmath>

#include "nonlinear_law.h"

namespace surgsim {

SurfaceDeformer::SurfaceDeformer(const TetMesh& mesh, const SurfaceMesh& surface, const Tensors* tensors,
                                 const NonlinearLaw* law)
    : law_(law) {
  // Compact the boundary to its own vertices (the GPU never sees interior nodes).
  visible_nodes_ = surface.nodes;
  vertex_of_node_.assign(static_cast<std::size_t>(mesh.nodes.rows()), -1);
  for (std::size_t v = 0; v < visible_nodes_.size(); ++v) {
    vertex_of_node_[static_cast<std::size_t>(visible_nodes_[v])] = static_cast<int>(v);
  }
  tris_.resize(surface.tris.rows(), 3);
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f) {
    for (int e = 0; e < 3; ++e) tris_(f, e) = vertex_of_node_[static_cast<std::size_t>(surface.tris(f, e))];
  }
  rest_.resize(static_cast<Eigen::Index>(visible_nodes_.size()), 3);
  for (std::size_t v = 0; v < visible_nodes_.size(); ++v) {
    rest_.row(static_cast<Eigen::Index>(v)) = mesh.nodes.row(visible_nodes_[v]).cast<float>();
  }
  positions_ = rest_;
  if (tensors == nullptr) return;

  superposition_ = std::make_unique<Superposition>(*tensors, "visual", kMaxContacts);
  const TensorBlock& block = superposition_->block();
  u_.setZero(3 * block.row_count());
  block_row_.assign(visible_nodes_.size(), -1);
  for (std::size_t v = 0; v < visible_nodes_.size(); ++v) {
    block_row_[v] = block.row_of_node[static_cast<std::size_t>(visible_nodes_[v])];
  }
}

ContactStatus SurfaceDeformer::apply(const int* nodes, const Eigen::Vector3d* lambda, int m,
                                     const Eigen::Vector3d& direction) noexcept {
  if (m == 0 || superposition_ == nullptr) {
    positions_ = rest_;
    max_displacement_ = 0;
    return m == 0 ? ContactStatus::kOk : ContactStatus::kNotContactable;
  }
  if (m > kMaxContacts) return ContactStatus::kOverCapacity;
  const ContactStatus status = superposition_->displacements(nodes, lambda, m, u_);
  if (status != ContactStatus::kOk) return status;
  // Quasi non-linear law: P on the amplitude orthogonal to the constraint direction, every row in place.
  if (law_ != nullptr && direction.squaredNorm() > 0.5 && !law_->apply_displacements(u_, direction)) {
    return ContactStatus::kNonFinite;
  }
  double max2 = 0;
  for (Eigen::Index v = 0; v < rest_.rows(); ++v) {
    const int r = block_row_[static_cast<std::size_t>(v)];
    if (r < 0) {
      positions_.row(v) = rest_.row(v);
      continue;
    }
    const Eigen::Vector3d u = u_.segment<3>(3 * r);
    max2 = std::max(max2, u.squaredNorm());
    positions_.row(v) = rest_.row(v) + u.cast<float>().transpose();
  }
  max_displacement_ = std::sqrt(max2);
  return ContactStatus::kOk;
}

}  // namespace surgsim
