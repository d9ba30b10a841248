// An elastic body's material, its regions of other materials and its fixed (clamped) region (docs/DESIGN.md, section
// 'Liver: precomputed linear elasticity'). Read from YAML by scene/; nothing here knows about scenes.
#pragma once
#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "mesh/mesh.h"
#include "mesh/placement.h"

namespace surgsim::fem {

/// The points x with sum(((x - center) / radii)^2) <= 1 (axis-aligned in the frame it is written in).
struct Ellipsoid {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();  // m
  Eigen::Vector3d radii = Eigen::Vector3d::Ones();   // m, each > 0
  bool contains(const Eigen::Vector3d& x) const { return ((x - center).array() / radii.array()).square().sum() <= 1; }
};

/// A part of one organ's mesh with its own material (heterogeneous tissue: the gallbladder, softer, in the liver's
/// fossa). It holds the elements whose centroid lies in one of its boxes (bounds inclusive) or ellipsoids, written in
/// the organ's own frame (Material::frame).
struct MaterialRegion {
  std::string name;
  double young_modulus = 3000.0;                                   // Pa, > 0
  double poisson_ratio = 0.45;                                     // [0, 0.5)
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> boxes;  // (min, max), m; min < max
  std::vector<Ellipsoid> ellipsoids;
  /// Where it was written ("scene.yaml:12: key 'material.regions[0]'"), to prefix its errors; may be empty.
  std::string where;

  /// True if a point in the organ's frame (m) is inside one of its boxes or ellipsoids.
  bool contains(const Eigen::Vector3d& x_organ) const;
};

struct Material {
  Material() = default;
  /// One material throughout (no regions): Material{3000, 0.45}.
  Material(double young, double poisson) : young_modulus(young), poisson_ratio(poisson) {}

  double young_modulus = 3000.0;  // Pa, > 0
  double poisson_ratio = 0.45;    // [0, 0.5)
  /// Regions with their own material, a later one over an earlier one; an element in none has the two values above.
  /// Empty for a homogeneous organ (every assembly, hash and cache is then what it was before regions existed).
  std::vector<MaterialRegion> regions;
  /// The frame the regions are written in: the organ's own, as FixedRegion::frame (a placed organ's mesh is in the
  /// scene's frame; its centroids are tested at frame.to_organ(x)). Identity for an organ at the origin.
  mesh::Placement frame;

  /// The base material alone (no regions): what a region-less consumer reads.
  Material base() const { return Material(young_modulus, poisson_ratio); }
};

/// Each element's material: materials[0] is the base, materials[1 + r] region r's (none with regions);
/// element[t] is the index of tet t's.
struct ElementMaterials {
  std::vector<Material> materials;
  std::vector<int> element;
};

/// Resolves the regions on a mesh (its nodes in the scene's frame) by tet centroid. Throws surgsim::core::Error, naming
/// the region, when a region holds no element at all (it would change nothing: a selector in the wrong place or
/// frame). `where` prefixes errors of a region with no `where` of its own.
ElementMaterials element_materials(const mesh::TetMesh& mesh, const Material& material, const std::string& where = "");

/// Fixed (clamped) nodes: the union of an index list, axis-aligned boxes and the negative side of a plane.
/// YAML: `fixed: {nodes: [..], box: {min, max}, boxes: [{min, max}, ..], plane: {point, normal}}`, all optional.
/// The single `box` key is one more entry of `boxes` (after it, before the list's boxes): one representation.
struct FixedRegion {
  std::vector<int> nodes;                                          // 0-based node indices in file order
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> boxes;  // (min, max) per box, m; min < max
  bool has_plane = false;
  Eigen::Vector3d plane_point = Eigen::Vector3d::Zero();    // m
  Eigen::Vector3d plane_normal = Eigen::Vector3d::UnitZ();  // unit; nodes with (x - point) . normal >= 0 are fixed
  /// The frame the boxes and the plane are written in: the organ's own (a placed organ's mesh is in the scene's
  /// frame; its nodes are tested at frame.to_organ(x)). Identity for an organ at the origin.
  mesh::Placement frame;

  /// True if node `index` at rest position `x` (m, the scene's frame) is fixed: listed, inside a box (bounds inclusive) or on
  /// the fixed side of the plane.
  bool fixes(int index, const Eigen::Vector3d& x) const;
  /// True if nothing at all is fixed by this region.
  bool empty() const { return nodes.empty() && boxes.empty() && !has_plane; }
};

}  // namespace surgsim::fem
