#include "views/rigid_view.h"

#include <nlohmann/json.hpp>

#include "mesher/scene_mesh.h"

namespace surgsim {

RigidView::RigidView(const scene::Scene& scene) : name_(scene.organs.at(0).name), cavity_(scene.rigid.cavity) {
  const mesh::TriSurface surface = mesher::load_scene_surface(scene);
  hash_ = mesher::rigid_surface_hash(surface, scene.rigid.cavity);
  positions_ = surface.vertices.cast<float>();
  tris_ = surface.tris;
  // Bone for bars (ribs, a spine segment, a box), the parietal peritoneum's pale pink for walls.
  const std::string& g = scene.rigid.generate;
  const bool bone = g == "ribs" || g == "tube" || g == "box";
  look_.rgb = bone ? Eigen::Vector3f(0.86f, 0.83f, 0.74f) : Eigen::Vector3f(0.78f, 0.52f, 0.50f);
}

void RigidView::add_stats(nlohmann::json& j) const {
  j["model_built"] = "rigid";
  j["rigid"] = {{"triangles", tris_.rows()}, {"cavity", cavity_}};
}

}  // namespace surgsim
