#include "views/surface_deformer.h"

#include <Eigen/Geometry>
#include <cmath>

#include "contact/bucket_grid.h"
#include "core/error.h"

#include "nonlinear/nonlinear_law.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::contact;

namespace surgsim {

SurfaceDeformer::SurfaceDeformer(const TetMesh& mesh, const SurfaceMesh& surface, const Tensors* tensors,
                                 const NonlinearLaw* law, LiverDeformation deformation)
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
  u_sum_.setZero(3 * block.row_count());
  group_nodes_.assign(kMaxContacts, 0);
  group_lambda_.assign(kMaxContacts, Eigen::Vector3d::Zero());
  block_row_.assign(visible_nodes_.size(), -1);
  for (std::size_t v = 0; v < visible_nodes_.size(); ++v) {
    block_row_[v] = block.row_of_node[static_cast<std::size_t>(visible_nodes_[v])];
  }
  if (deformation == LiverDeformation::kCorotational) {
    rotations_ = std::make_unique<NodeRotations>(mesh, surface);
    rest_lambda_.assign(kMaxContacts, Eigen::Vector3d::Zero());
  }
}

ContactStatus SurfaceDeformer::displace(const int* nodes, const Eigen::Vector3d* lambda, int m, Eigen::VectorXd& u,
                                        bool rotate_rows) noexcept {
  if (rotations_ == nullptr) return superposition_->displacements(nodes, lambda, m, u);
  if (m > kMaxContacts) return ContactStatus::kOverCapacity;
  for (int l = 0; l < m; ++l) {
    const int n = nodes[l];
    if (n < 0 || n >= rotations_->node_count()) return ContactStatus::kInvalidNode;
    rest_lambda_[static_cast<std::size_t>(l)] = rotations_->rotation(n).transpose() * lambda[l];
  }
  const ContactStatus status = superposition_->displacements(nodes, rest_lambda_.data(), m, u);
  if (status != ContactStatus::kOk || !rotate_rows) return status;
  const TensorBlock& block = superposition_->block();
  for (int r = 0; r < block.row_count(); ++r)
    u.segment<3>(3 * r) = rotations_->rotation(block.row_nodes[static_cast<std::size_t>(r)]) * u.segment<3>(3 * r);
  return ContactStatus::kOk;
}

ContactStatus SurfaceDeformer::update_rotations(const int* nodes, const Eigen::Vector3d* lambda, int m) noexcept {
  if (rotations_ == nullptr) return ContactStatus::kOk;
  const TensorBlock& block = superposition_->block();
  const auto disp = [&](int k) -> Eigen::Vector3d {
    const int r = block.row_of_node[static_cast<std::size_t>(k)];
    return r >= 0 ? Eigen::Vector3d(u_.segment<3>(3 * r)) : Eigen::Vector3d::Zero();
  };
  for (int pass = 0; pass < kCorotationalPasses; ++pass) {
    const ContactStatus status = displace(nodes, lambda, m, u_, false);  // the rest-frame response
    if (status != ContactStatus::kOk) return status;
    for (const int n : visible_nodes_) rotations_->update(n, disp);
  }
  return ContactStatus::kOk;
}

void SurfaceDeformer::embed(const TriSurface& fine, const TetMesh& mesh, const SurfaceMesh& surface,
                            double max_distance) {
  const BucketGrid grid(mesh, surface);
  const Eigen::Index n = fine.vertices.rows();
  fine_anchor_.resize(n, 3);
  fine_bary_.resize(n, 3);
  fine_offset_.resize(n);
  // Vertices no face uses are never drawn: tie them to the first boundary vertex and skip the search.
  std::vector<char> used(static_cast<std::size_t>(n), 0);
  for (Eigen::Index t = 0; t < fine.tris.rows(); ++t) {
    for (int k = 0; k < 3; ++k) used[static_cast<std::size_t>(fine.tris(t, k))] = 1;
  }
  for (Eigen::Index v = 0; v < n; ++v) {
    if (!used[static_cast<std::size_t>(v)]) {
      fine_anchor_.row(v).setZero();
      fine_bary_.row(v) << 1.0f, 0.0f, 0.0f;
      fine_offset_[v] = 0.0f;
      continue;
    }
    const Eigen::Vector3d p = fine.vertices.row(v).transpose();
    const SurfaceProjection proj = grid.project_rest(p, 4);
    if (!proj.found || proj.distance > max_distance) {
      throw_error(fine.source, ": vertex ", v + 1, " at (", p.transpose(), ") is ",
                  proj.found ? std::to_string(proj.distance) + " m" : std::string("far"),
                  " from the organ's boundary (limit ", max_distance,
                  " m): the visual surface must lie on the mechanical mesh (same units and placement)");
    }
    for (int k = 0; k < 3; ++k) fine_anchor_(v, k) = vertex_of(proj.nodes[static_cast<std::size_t>(k)]);
    fine_bary_.row(v) = proj.bary.cast<float>().transpose();
    fine_offset_[v] = static_cast<float>((p - proj.point).dot(proj.normal));
  }
  fine_tris_ = fine.tris;
  fine_positions_.resize(n, 3);
  update_fine();
}

void SurfaceDeformer::update_fine() noexcept {
  for (Eigen::Index v = 0; v < fine_anchor_.rows(); ++v) {
    const Eigen::Vector3f a = positions_.row(fine_anchor_(v, 0)).transpose();
    const Eigen::Vector3f b = positions_.row(fine_anchor_(v, 1)).transpose();
    const Eigen::Vector3f c = positions_.row(fine_anchor_(v, 2)).transpose();
    Eigen::Vector3f normal = (b - a).cross(c - a);
    const float len = normal.norm();
    if (len > 0) normal /= len;
    fine_positions_.row(v) =
        (fine_bary_(v, 0) * a + fine_bary_(v, 1) * b + fine_bary_(v, 2) * c + fine_offset_[v] * normal).transpose();
  }
}

ContactStatus SurfaceDeformer::apply(const int* nodes, const Eigen::Vector3d* lambda, int m,
                                     const Eigen::Vector3d& direction) noexcept {
  if (m == 0 || superposition_ == nullptr) {
    if (rotations_ != nullptr) rotations_->reset();
    positions_ = rest_;
    max_displacement_ = 0;
    update_fine();
    return m == 0 ? ContactStatus::kOk : ContactStatus::kNotContactable;
  }
  if (m > kMaxContacts) return ContactStatus::kOverCapacity;
  ContactStatus status = update_rotations(nodes, lambda, m);
  if (status == ContactStatus::kOk) status = displace(nodes, lambda, m, u_);
  if (status != ContactStatus::kOk) return status;
  // Quasi non-linear law: P on the amplitude orthogonal to the constraint direction, every row in place.
  if (law_ != nullptr && direction.squaredNorm() > 0.5 && !law_->apply_displacements(u_, direction)) {
    return ContactStatus::kNonFinite;
  }
  set_shape(u_);
  return ContactStatus::kOk;
}

ContactStatus SurfaceDeformer::apply(const int* nodes, const Eigen::Vector3d* lambda, const int* instrument, int m,
                                     const Eigen::Vector3d* directions, int instruments) noexcept {
  // The law's group of contact l: its instrument when that has a direction, else `instruments` (linear).
  const auto group = [&](int l) {
    const int i = instrument[l];
    return law_ != nullptr && i >= 0 && i < instruments && directions[i].squaredNorm() > 0.5 ? i : instruments;
  };
  if (m <= 0 || m > kMaxContacts || superposition_ == nullptr) return apply(nodes, lambda, m);
  const int first = group(0);
  bool one_group = true;
  for (int l = 1; l < m && one_group; ++l) one_group = group(l) == first;
  if (one_group) return apply(nodes, lambda, m, first < instruments ? directions[first] : Eigen::Vector3d::Zero());

  // Each group's share u_g = sum_{l in g} G(., k_l) lambda_l, bent about its direction, added up (corotational: the
  // rotations from all contacts together, each share warped by them).
  const ContactStatus rotated = update_rotations(nodes, lambda, m);
  if (rotated != ContactStatus::kOk) return rotated;
  u_sum_.setZero();
  for (int g = 0; g <= instruments; ++g) {
    int count = 0;
    for (int l = 0; l < m; ++l) {
      if (group(l) != g) continue;
      group_nodes_[static_cast<std::size_t>(count)] = nodes[l];
      group_lambda_[static_cast<std::size_t>(count)] = lambda[l];
      ++count;
    }
    if (count == 0) continue;
    const ContactStatus status = displace(group_nodes_.data(), group_lambda_.data(), count, u_);
    if (status != ContactStatus::kOk) return status;
    if (g < instruments && !law_->apply_displacements(u_, directions[g])) return ContactStatus::kNonFinite;
    u_sum_ += u_;
  }
  set_shape(u_sum_);
  return ContactStatus::kOk;
}

bool SurfaceDeformer::set_positions(const double* xyz, int count) noexcept {
  if (count != rest_.rows()) return false;
  for (int i = 0; i < 3 * count; ++i) {
    if (!std::isfinite(xyz[i])) return false;
  }
  double max2 = 0;
  for (Eigen::Index v = 0; v < rest_.rows(); ++v) {
    const Eigen::Vector3d p(xyz[3 * v], xyz[3 * v + 1], xyz[3 * v + 2]);
    positions_.row(v) = p.cast<float>().transpose();
    max2 = std::max(max2, (p - rest_.row(v).transpose().cast<double>()).squaredNorm());
  }
  max_displacement_ = std::sqrt(max2);
  update_fine();
  return true;
}

ContactStatus SurfaceDeformer::carry_positions(const double* xyz, int count, const Contact* contacts, int m) noexcept {
  if (count != rest_.rows()) return ContactStatus::kInvalidNode;
  if (m == 0) return set_positions(xyz, count) ? ContactStatus::kOk : ContactStatus::kNonFinite;
  if (superposition_ == nullptr) return ContactStatus::kNotContactable;
  if (m < 0 || m > kMaxContacts) return ContactStatus::kOverCapacity;
  for (int l = 0; l < m; ++l) {
    const int v = vertex_of(contacts[l].node);
    if (v < 0) return ContactStatus::kNotInBlock;
    const Eigen::Vector3d at(xyz[3 * v], xyz[3 * v + 1], xyz[3 * v + 2]);
    carry_[static_cast<std::size_t>(l)].node = contacts[l].node;
    carry_[static_cast<std::size_t>(l)].displacement =
        contacts[l].displacement - (at - rest_.row(v).transpose().cast<double>());
  }
  const ContactStatus solved = superposition_->solve(carry_.data(), m, carry_solution_);
  if (solved != ContactStatus::kOk) return solved;
  const ContactStatus status = superposition_->displacements(carry_solution_.nodes.data(), carry_solution_.lambda.data(),
                                                             carry_solution_.count, u_);
  if (status != ContactStatus::kOk) return status;
  if (!u_.allFinite()) return ContactStatus::kNonFinite;
  for (int i = 0; i < 3 * count; ++i) {
    if (!std::isfinite(xyz[i])) return ContactStatus::kNonFinite;
  }
  double max2 = 0;
  for (Eigen::Index v = 0; v < rest_.rows(); ++v) {
    Eigen::Vector3d p(xyz[3 * v], xyz[3 * v + 1], xyz[3 * v + 2]);
    const int r = block_row_[static_cast<std::size_t>(v)];
    if (r >= 0) p += u_.segment<3>(3 * r);
    positions_.row(v) = p.cast<float>().transpose();
    max2 = std::max(max2, (p - rest_.row(v).transpose().cast<double>()).squaredNorm());
  }
  max_displacement_ = std::sqrt(max2);
  update_fine();
  return ContactStatus::kOk;
}

void SurfaceDeformer::set_shape(const Eigen::VectorXd& u_all) noexcept {
  double max2 = 0;
  for (Eigen::Index v = 0; v < rest_.rows(); ++v) {
    const int r = block_row_[static_cast<std::size_t>(v)];
    if (r < 0) {
      positions_.row(v) = rest_.row(v);
      continue;
    }
    const Eigen::Vector3d u = u_all.segment<3>(3 * r);
    max2 = std::max(max2, u.squaredNorm());
    positions_.row(v) = rest_.row(v) + u.cast<float>().transpose();
  }
  max_displacement_ = std::sqrt(max2);
  update_fine();
}

}  // namespace surgsim
