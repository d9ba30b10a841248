// A rigid organ in the visual node (an entry `model: rigid` of a scene's `organs:` list: the abdominal wall, ribs, a
// spine segment): its surface, built as the haptic node builds it (mesher::load_scene_surface), drawn every frame
// as it is; it never deforms and takes nothing from the contact frames.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <string>

#include "organ_view.h"
#include "render/renderer.h"

namespace surgsim {

class RigidView final : public OrganView {
 public:
  /// Init: the surface of `scene` (an organ_scene() of a rigid organ). Throws surgsim::core::Error naming the scene
  /// file and the organ.
  explicit RigidView(const scene::Scene& scene);

  /// The surface's identity (the haptic node's RigidOrgan::mesh_hash).
  std::uint64_t mesh_hash() const override { return hash_; }
  long surface_triangles() const override { return static_cast<long>(tris_.rows()); }
  double update(const msg::ContactFrame*, bool) noexcept override { return -1; }
  void draw(Renderer& renderer) const override { renderer.draw_surface(positions_, tris_, look_, &tint_); }
  /// A cavity (seen from inside, around everything) after the other opaque organs; else its bounding box's centre.
  double draw_depth(const Eigen::Vector3d& eye) const override;
  void add_stats(nlohmann::json& stats) const override;

 private:
  std::string name_;
  Eigen::MatrixX3f positions_;
  Eigen::MatrixX3i tris_;
  SurfaceLook look_;
  Eigen::MatrixX3f tint_;  // per vertex, from its position (render/surface_detail.h)
  std::uint64_t hash_ = 0;
  bool cavity_ = false;
};

}  // namespace surgsim
