// What the liver benchmarks share (liver_error_bench, large_deformation_bench): the scene's organ ready to solve,
// the flat punch of the non-linear study, the visible part of a whole-mesh solution, and the quasi non-linear law
// applied as the nodes apply it.
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "nonlinear/nonlinear_law.h"
#include "compliance/precompute.h"
#include "compliance/superposition.h"
#include "mesh/box_mesh.h"
#include "mesher/scene_mesh.h"
#include "scene/scene.h"

namespace surgsim::bench_liver {

inline const Eigen::Vector2d kPunchCentre(0.03, 0.0);  // m, x-y: the scene's tool comes down here
constexpr double kPunchRadius = 0.02;                  // m

// An organ ready to solve: the scene's material and clamp on a generated liver (or a liver-sized box).
struct Organ {
  std::string kind;               // "liver" | "box"
  mesh::TetMesh mesh;
  fem::FixedSet fixed;
  std::unique_ptr<fem::ElasticModel> model;
  std::vector<int> contacts;      // contactable (free boundary) nodes
  std::vector<compliance::RowSet> rows;  // "haptic", "visual"
  std::vector<int> visible;       // boundary nodes = the visual rows, in row order
  Eigen::MatrixX3d normals;       // #V x 3, unit outward normals on boundary nodes (0 inside)
  double height = 0;              // m, z extent
};

/// The scene's liver at `target_nodes` (meshes cached in `cache`), or with `box` a liver-sized structured box.
inline std::unique_ptr<Organ> make_organ(const scene::Scene& scene, int target_nodes, const std::string& cache,
                                         bool box) {
  auto o = std::make_unique<Organ>();
  if (!box) {
    scene::Scene sized = scene;
    sized.mesh.target_nodes = target_nodes;
    o->kind = "liver";
    o->mesh = mesher::load_scene_mesh(sized, cache, nullptr);
  }
  if (o->mesh.nodes.rows() == 0) {
    // The liver's bounding box (x [-0.13, 0.13], y [-0.08, 0.08], z [-0.04, 0.04] m), structured.
    o->kind = "box";
    o->mesh = mesh::make_box_mesh_with_nodes(target_nodes, Eigen::Vector3d(0.26, 0.16, 0.08));
    o->mesh.nodes.rowwise() -= Eigen::RowVector3d(0.13, 0.08, 0.04);
  }
  o->fixed = fem::fixed_set_from_region(o->mesh, scene.fixed);
  o->model =
      std::make_unique<fem::ElasticModel>(fem::build_elastic_model(o->mesh, scene.material, o->fixed, scene.file));
  o->contacts = compliance::contactable_nodes(o->mesh, o->fixed);
  o->rows = compliance::standard_row_sets(o->mesh, o->contacts);
  for (const auto& r : o->rows)
    if (r.name == "visual") o->visible = r.nodes;
  const mesh::SurfaceMesh surface = mesh::boundary_surface(o->mesh);
  o->normals.setZero(o->mesh.nodes.rows(), 3);
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f) {
    const Eigen::RowVector3d a = o->mesh.nodes.row(surface.tris(f, 0)), b = o->mesh.nodes.row(surface.tris(f, 1)),
                             c = o->mesh.nodes.row(surface.tris(f, 2));
    const Eigen::RowVector3d n = (b - a).cross(c - a);
    for (int k = 0; k < 3; ++k) o->normals.row(surface.tris(f, k)) += n;
  }
  o->normals.rowwise().normalize();
  o->normals = o->normals.unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; });
  o->height = o->mesh.nodes.col(2).maxCoeff() - o->mesh.nodes.col(2).minCoeff();
  return o;
}

/// The flat punch: free top-surface nodes (normal z > 0.5) within `radius` of `centre` in x-y.
inline std::vector<int> punch_nodes(const Organ& o, const Eigen::Vector2d& centre = kPunchCentre,
                                    double radius = kPunchRadius) {
  std::vector<int> out;
  for (int k : o.contacts)
    if (o.normals(k, 2) > 0.5 && (o.mesh.nodes.row(k).head<2>().transpose() - centre).norm() <= radius)
      out.push_back(k);
  return out;
}

/// The displacements of the visible nodes (3R, row order of Organ::visible) from a whole-mesh solution.
inline Eigen::VectorXd visible_part(const Organ& o, const Eigen::MatrixX3d& u) {
  Eigen::VectorXd out(3 * static_cast<Eigen::Index>(o.visible.size()));
  for (std::size_t r = 0; r < o.visible.size(); ++r)
    out.segment<3>(3 * static_cast<Eigen::Index>(r)) = u.row(o.visible[r]).transpose();
  return out;
}

inline double rel(double err, double scale) { return err / std::max(scale, 1e-300); }

/// The quasi non-linear law as the nodes apply it: the haptic node's Q (the organ law: its surface field at the
/// contact nodes) on the tool force `force` along the mean imposed displacement (`imposed`, `m` of them;
/// common/contact/tool_contacts.cpp), the visual node's P on every visible row of `u` (3R, the "visual" block's rows)
/// along the direction of the summed rows of the contact nodes (visual_node/views/surface_deformer.cpp).
inline void apply_quasi(const nonlinear::NonlinearLaw& law, const Eigen::Vector3d* imposed, int m, const int* nodes,
                        const compliance::TensorBlock& visual, Eigen::Vector3d& force, Eigen::VectorXd& u) {
  Eigen::Vector3d dir;
  if (nonlinear::constraint_direction(imposed, m, dir)) law.apply_force(force, dir, nodes, imposed, m, force);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int l = 0; l < m; ++l) sum += u.segment<3>(3 * visual.row_of_node[static_cast<std::size_t>(nodes[l])]);
  if (nonlinear::constraint_direction(&sum, 1, dir)) law.apply_displacements(u, dir);
}

}  // namespace surgsim::bench_liver
