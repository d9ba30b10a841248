// Linear-elastic P1 tetrahedral finite elements (docs/DESIGN.md, section 'Liver: precomputed linear elasticity'):
// element and global stiffness, and the assembled model every liver solver shares. Pure: Eigen only.
#pragma once
#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "fem/fixed_set.h"
#include "mesh/mesh.h"
#include "fem/material.h"

namespace surgsim::fem {

/// Throws surgsim::core::Error unless 0 < young_modulus < inf and 0 <= poisson_ratio < 0.5 (0.5 is incompressible: the
/// displacement formulation locks and the elasticity matrix is singular), for the base and every region.
void check_material(const Material& material);

/// Isotropic elasticity matrix (Voigt order xx, yy, zz, xy, yz, xz with engineering shear strains), Pa, of the base
/// material (its regions are not read).
Eigen::Matrix<double, 6, 6> elasticity_matrix(const Material& material);

/// Stiffness of one P1 tetrahedron with corner positions x (4 x 3, m), N/m, of the base material (its regions are
/// not read). Dof order: node 0 x, y, z, node 1 ... Throws surgsim::core::Error on a degenerate or inverted tet.
Eigen::Matrix<double, 12, 12> tet_stiffness(const Eigen::Matrix<double, 4, 3>& x, const Material& material);

/// Global stiffness K (3N x 3N, N/m, dof 3 n + c), symmetric, both triangles stored, column-major. Singular (6 rigid
/// modes) until fixed dofs are removed. Throws surgsim::core::Error on a bad material or an inverted/degenerate tet
/// (run validate_mesh first). Each tet has its own material: the region holding its centroid, else the base
/// (element_materials; a material without regions assembles every tet with one elasticity matrix, as before regions).
Eigen::SparseMatrix<double> assemble_stiffness(const mesh::TetMesh& mesh, const Material& material);
/// The same with the materials already resolved (`elements.element` has one entry per tet).
Eigen::SparseMatrix<double> assemble_stiffness(const mesh::TetMesh& mesh, const ElementMaterials& elements);

/// Rows and columns of the free dofs of `fixed` (K_ff in fixed.free_index() numbering). Both triangles.
Eigen::SparseMatrix<double> free_stiffness(const Eigen::SparseMatrix<double>& k, const FixedSet& fixed);

/// Tets a displacement field turns inside out: the deformed signed volume det[x1-x0, x2-x0, x3-x0] / 6 of each tet
/// against its rest volume. Linear elasticity keeps going where the real tissue could not: a displacement larger
/// than an element (a deep poke) inverts the tets next to it, and this says so.
struct TetInversion {
  int inverted = 0;             // tets whose deformed volume is <= 0 (or not finite)
  int worst_tet = -1;           // tet with the smallest deformed / rest volume ratio (-1 for an empty mesh)
  double min_volume_ratio = 1;  // that ratio (negative: inverted)
};
/// `displacement` #V x 3 (m). Throws surgsim::core::Error on a size mismatch. Cheap: one determinant per tet.
TetInversion count_inverted_tets(const mesh::TetMesh& mesh, const Eigen::MatrixX3d& displacement);

/// An assembled linear-elastic organ: the immutable model every liver solver and the precomputation read.
/// The mesh is referenced, not copied: it must outlive the model.
struct ElasticModel {
  const mesh::TetMesh* mesh = nullptr;
  Material material;          // the organ's, with its regions
  ElementMaterials elements;  // each tet's material (resolved from `material` on the mesh)
  FixedSet fixed;
  Eigen::SparseMatrix<double> k;     // K, 3N x 3N, N/m
  Eigen::SparseMatrix<double> k_ff;  // K_ff, free x free (fixed.free_index() numbering), N/m, SPD

  int node_count() const { return static_cast<int>(mesh->nodes.rows()); }
};

/// Checks the material, resolves its regions (element_materials) and the fixed set (check_rigid_modes_removed),
/// assembles K and K_ff.
/// `where` prefixes error messages (e.g. the scene file). Throws surgsim::core::Error.
ElasticModel build_elastic_model(const mesh::TetMesh& mesh, const Material& material, const FixedSet& fixed,
                                 const std::string& where = "");

}  // namespace surgsim::fem
