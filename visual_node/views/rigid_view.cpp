#include "views/rigid_view.h"

#include <nlohmann/json.hpp>

#include "mesher/scene_mesh.h"
#include "render/surface_detail.h"

namespace surgsim {

RigidView::RigidView(const scene::Scene& scene) : name_(scene.organs.at(0).name), cavity_(scene.rigid.cavity) {
  const mesh::TriSurface surface = mesher::load_scene_surface(scene);
  hash_ = mesher::rigid_surface_hash(surface, scene.rigid.cavity);
  positions_ = surface.vertices.cast<float>();
  tris_ = surface.tris;
  // The organ's colour (organ_rgb: bone for bars, pinkish red for walls), a wet highlight, and its detail: walls
  // mottled with vessel-like streaks, bone faintly mottled.
  const scene::OrganSpec& organ = scene.organs.at(0);
  look_ = SurfaceLook{organ_rgb(organ), 0.25f, 70.0f};
  const bool bone = organ_is_bone(organ);
  SurfaceDetail detail;
  detail.seed = static_cast<std::uint32_t>(hash_);
  if (bone) {
    detail.scale = 60.0f;
    detail.mottle = 0.06f;
    detail.hue = 0.02f;
  } else {
    detail.scale = 30.0f;
    detail.mottle = 0.10f;
    detail.streaks = 0.7f;
    detail.streak_scale = 12.0f;
  }
  tint_ = surface_tint(positions_, detail);
}

double RigidView::draw_depth(const Eigen::Vector3d& eye) const {
  if (cavity_) return 1e9;
  const Eigen::Vector3f centre = 0.5f * (positions_.colwise().minCoeff() + positions_.colwise().maxCoeff()).transpose();
  return (centre.cast<double>() - eye).norm();
}

void RigidView::add_stats(nlohmann::json& j) const {
  j["model_built"] = "rigid";
  j["rigid"] = {{"triangles", tris_.rows()}, {"cavity", cavity_}};
}

}  // namespace surgsim
