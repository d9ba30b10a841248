#include "fem/material.h"

#include <algorithm>

#include "core/error.h"

namespace surgsim::fem {

namespace {
bool in_box(const Eigen::Vector3d& x, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  return (x.array() >= lo.array()).all() && (x.array() <= hi.array()).all();
}
}  // namespace

bool MaterialRegion::contains(const Eigen::Vector3d& x) const {
  for (const auto& b : boxes)
    if (in_box(x, b.first, b.second)) return true;
  for (const auto& e : ellipsoids)
    if (e.contains(x)) return true;
  return false;
}

ElementMaterials element_materials(const mesh::TetMesh& mesh, const Material& material, const std::string& where) {
  ElementMaterials out;
  out.materials.push_back(material.base());
  out.element.assign(static_cast<std::size_t>(mesh.tets.rows()), 0);
  if (material.regions.empty()) return out;
  std::vector<int> held(material.regions.size(), 0);  // elements each region selects (before later ones override)
  for (Eigen::Index t = 0; t < mesh.tets.rows(); ++t) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int a = 0; a < 4; ++a) c += mesh.nodes.row(mesh.tets(t, a)).transpose();
    const Eigen::Vector3d x = material.frame.to_organ(c / 4);
    for (std::size_t r = material.regions.size(); r-- > 0;) {  // the last region holding it wins
      if (!material.regions[r].contains(x)) continue;
      out.element[static_cast<std::size_t>(t)] = static_cast<int>(r) + 1;
      ++held[r];
      break;
    }
  }
  for (std::size_t r = 0; r < material.regions.size(); ++r) {
    const MaterialRegion& region = material.regions[r];
    out.materials.push_back(Material(region.young_modulus, region.poisson_ratio));
    if (held[r] > 0) continue;
    const std::string at = !region.where.empty() ? region.where : where.empty() ? std::string("material") : where;
    core::throw_error(
        at, ": material region '", region.name, "' holds no element of ",
        mesh.source.empty() ? std::string("the mesh") : "mesh " + mesh.source, " (", mesh.tets.rows(),
        " tets): no tet centroid lies in its boxes or ellipsoids, or a later region takes every one that does (give "
        "its box or ellipsoid in the organ's own frame, around the elements it should hold, or remove it)");
  }
  return out;
}

bool FixedRegion::fixes(int index, const Eigen::Vector3d& x_scene) const {
  if (std::find(nodes.begin(), nodes.end(), index) != nodes.end()) return true;
  const Eigen::Vector3d x = frame.to_organ(x_scene);
  for (const auto& b : boxes) {
    if (in_box(x, b.first, b.second)) return true;
  }
  return has_plane && (x - plane_point).dot(plane_normal) >= 0;
}

}  // namespace surgsim::fem
