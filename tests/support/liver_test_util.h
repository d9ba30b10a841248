// Shared helpers for the liver physics tests: small organs built from structured meshes, and error norms.
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "mesh/box_mesh.h"
#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "mesh/mesh.h"
#include "scene/scene.h"

namespace surgsim::test {

/// A mesh, its material and fixed set, and the assembled model pointing at them (not movable: the model holds a
/// pointer to the mesh).
struct Organ {
  mesh::TetMesh mesh;
  fem::Material material;
  fem::FixedSet fixed;
  fem::ElasticModel model;

  Organ(mesh::TetMesh m, const fem::Material& mat, fem::FixedSet f)
      : mesh(std::move(m)),
        material(mat),
        fixed(std::move(f)),
        model(fem::build_elastic_model(mesh, material, fixed)) {}
  Organ(const Organ&) = delete;
  Organ& operator=(const Organ&) = delete;
};

inline fem::Material liver_material() {
  fem::Material m;
  m.young_modulus = 3000.0;  // Pa
  m.poisson_ratio = 0.45;
  return m;
}

/// A liver-sized box (0.16 x 0.12 x 0.08 m) of nx x ny x nz cells, clamped on its bottom face (z = 0).
inline std::unique_ptr<Organ> box_organ(int nx = 8, int ny = 6, int nz = 4,
                                        mesh::BoxSplit split = mesh::BoxSplit::kSix) {
  mesh::TetMesh mesh =
      mesh::make_box_mesh(nx, ny, nz, Eigen::Vector3d(0.16, 0.12, 0.08), Eigen::Vector3d::Zero(), split);
  fem::FixedRegion region;
  region.has_plane = true;
  region.plane_point = Eigen::Vector3d::Zero();
  region.plane_normal = -Eigen::Vector3d::UnitZ();  // z <= 0 fixed
  fem::FixedSet fixed = fem::fixed_set_from_region(mesh, region);
  return std::make_unique<Organ>(std::move(mesh), liver_material(), std::move(fixed));
}

/// |a - b| / |b| (max norm over all entries), with |b| floored at `floor`.
template <typename A, typename B>
double rel_error(const A& a, const B& b, double floor = 1e-300) {
  return (a - b).cwiseAbs().maxCoeff() / std::max(b.cwiseAbs().maxCoeff(), floor);
}

/// Top nodes of box_organ (z = 0.08) within `radius` of (x, y) in the xy plane.
inline std::vector<int> top_patch(const mesh::TetMesh& mesh, double x, double y, double radius) {
  std::vector<int> out;
  for (int i = 0; i < mesh.nodes.rows(); ++i)
    if (std::abs(mesh.nodes(i, 2) - 0.08) < 1e-9 && std::hypot(mesh.nodes(i, 0) - x, mesh.nodes(i, 1) - y) <= radius)
      out.push_back(i);
  return out;
}

/// m distinct random picks from `pool`.
inline std::vector<int> pick(const std::vector<int>& pool, int m, std::mt19937& rng) {
  std::vector<int> p = pool;
  std::shuffle(p.begin(), p.end(), rng);
  p.resize(static_cast<std::size_t>(m));
  return p;
}

}  // namespace surgsim::test
