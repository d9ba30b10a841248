#include "fem/fem.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <vector>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::fem {

void check_material(const Material& material) {
  for (const MaterialRegion& r : material.regions) {
    try {
      check_material(Material(r.young_modulus, r.poisson_ratio));
    } catch (const Error& e) {
      throw_error(r.where.empty() ? std::string() : r.where + ": ", "material region '", r.name, "': ", e.what());
    }
  }
  if (!(material.young_modulus > 0) || !std::isfinite(material.young_modulus))
    throw_error("Young's modulus must be a positive number of pascals, got ", material.young_modulus);
  if (!(material.poisson_ratio >= 0) || !(material.poisson_ratio < 0.5))
    throw_error("Poisson ratio must be in [0, 0.5), got ", material.poisson_ratio,
                " (0.5 is incompressible and not supported by linear P1 elements; use e.g. 0.49)");
}

Eigen::Matrix<double, 6, 6> elasticity_matrix(const Material& material) {
  const double e = material.young_modulus, nu = material.poisson_ratio;
  const double c = e / ((1 + nu) * (1 - 2 * nu));
  Eigen::Matrix<double, 6, 6> d = Eigen::Matrix<double, 6, 6>::Zero();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) d(i, j) = c * (i == j ? 1 - nu : nu);
  for (int i = 3; i < 6; ++i) d(i, i) = c * (1 - 2 * nu) / 2;
  return d;
}

namespace {

// Stiffness with a precomputed elasticity matrix; returns false on a non-positive volume.
bool tet_stiffness_with(const Eigen::Matrix<double, 4, 3>& x, const Eigen::Matrix<double, 6, 6>& d,
                        Eigen::Matrix<double, 12, 12>& ke) {
  Eigen::Matrix3d edges;
  for (int a = 0; a < 3; ++a) edges.col(a) = (x.row(a + 1) - x.row(0)).transpose();
  const double det = edges.determinant();
  const double scale = edges.colwise().norm().maxCoeff();
  if (!(det > 1e-14 * scale * scale * scale)) return false;
  const double volume = det / 6;
  // Gradients of the barycentric shape functions: rows of edges^-1 for nodes 1..3, minus their sum for node 0.
  const Eigen::Matrix3d inv = edges.inverse();
  Eigen::Matrix<double, 4, 3> grad;
  grad.bottomRows<3>() = inv;
  grad.row(0) = -inv.colwise().sum();
  Eigen::Matrix<double, 6, 12> b = Eigen::Matrix<double, 6, 12>::Zero();
  for (int n = 0; n < 4; ++n) {
    const double gx = grad(n, 0), gy = grad(n, 1), gz = grad(n, 2);
    b(0, 3 * n) = gx;
    b(1, 3 * n + 1) = gy;
    b(2, 3 * n + 2) = gz;
    b(3, 3 * n) = gy;
    b(3, 3 * n + 1) = gx;
    b(4, 3 * n + 1) = gz;
    b(4, 3 * n + 2) = gy;
    b(5, 3 * n) = gz;
    b(5, 3 * n + 2) = gx;
  }
  ke.noalias() = volume * b.transpose() * d * b;
  return true;
}

}  // namespace

Eigen::Matrix<double, 12, 12> tet_stiffness(const Eigen::Matrix<double, 4, 3>& x, const Material& material) {
  check_material(material);
  Eigen::Matrix<double, 12, 12> ke;
  if (!tet_stiffness_with(x, elasticity_matrix(material), ke))
    throw_error("tet stiffness: degenerate or inverted tetrahedron (non-positive volume)");
  return ke;
}

Eigen::SparseMatrix<double> assemble_stiffness(const TetMesh& mesh, const Material& material) {
  check_material(material);
  return assemble_stiffness(mesh, element_materials(mesh, material, mesh.source));
}

Eigen::SparseMatrix<double> assemble_stiffness(const TetMesh& mesh, const ElementMaterials& elements) {
  for (const Material& m : elements.materials) check_material(m);
  if (elements.element.size() != static_cast<std::size_t>(mesh.tets.rows()))
    throw_error("assemble: ", elements.element.size(), " element materials for ", mesh.tets.rows(), " tets");
  for (int i : elements.element)
    if (i < 0 || static_cast<std::size_t>(i) >= elements.materials.size())
      throw_error("assemble: element material ", i, " outside 0..", elements.materials.size() - 1);
  const int n = static_cast<int>(mesh.nodes.rows());
  const Eigen::Index tets = mesh.tets.rows();

  // Node adjacency (including the node itself), sorted: the 3x3 block pattern of K.
  std::vector<std::vector<int>> adj(static_cast<std::size_t>(n));
  for (Eigen::Index t = 0; t < tets; ++t)
    for (int a = 0; a < 4; ++a) {
      const int i = mesh.tets(t, a);
      if (i < 0 || i >= n) throw_error("assemble: tet ", t, " refers to node ", i, " outside 0..", n - 1);
      for (int b = 0; b < 4; ++b) adj[static_cast<std::size_t>(i)].push_back(mesh.tets(t, b));
    }
  for (auto& v : adj) {
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
  }

  // Column 3j + c holds rows 3i + r for i in adj[j], r = 0..2, in order.
  Eigen::SparseMatrix<double> k(3 * n, 3 * n);
  std::vector<int> col_start(static_cast<std::size_t>(3 * n + 1), 0);
  for (int j = 0; j < n; ++j)
    for (int c = 0; c < 3; ++c)
      col_start[static_cast<std::size_t>(3 * j + c + 1)] =
          col_start[static_cast<std::size_t>(3 * j + c)] +
          3 * static_cast<int>(adj[static_cast<std::size_t>(j)].size());
  const int nnz = col_start.back();
  k.resizeNonZeros(nnz);
  std::copy(col_start.begin(), col_start.end(), k.outerIndexPtr());
  int* inner = k.innerIndexPtr();
  double* value = k.valuePtr();
  std::fill(value, value + nnz, 0.0);
  for (int j = 0; j < n; ++j)
    for (int c = 0; c < 3; ++c) {
      int p = col_start[static_cast<std::size_t>(3 * j + c)];
      for (int i : adj[static_cast<std::size_t>(j)])
        for (int r = 0; r < 3; ++r) inner[p++] = 3 * i + r;
    }

  std::vector<Eigen::Matrix<double, 6, 6>> d;
  for (const Material& m : elements.materials) d.push_back(elasticity_matrix(m));
  Eigen::Matrix<double, 4, 3> x;
  Eigen::Matrix<double, 12, 12> ke;
  for (Eigen::Index t = 0; t < tets; ++t) {
    for (int a = 0; a < 4; ++a) x.row(a) = mesh.nodes.row(mesh.tets(t, a));
    if (!tet_stiffness_with(x, d[static_cast<std::size_t>(elements.element[static_cast<std::size_t>(t)])], ke)) {
      const auto id = [&](int a) {
        const int node = mesh.tets(t, a);
        return mesh.ids.empty() ? static_cast<std::int64_t>(node) : mesh.ids[static_cast<std::size_t>(node)];
      };
      const std::int64_t tet_id =
          mesh.tet_ids.empty() ? static_cast<std::int64_t>(t) : mesh.tet_ids[static_cast<std::size_t>(t)];
      throw_error(mesh.source.empty() ? std::string("mesh") : mesh.source, ": tetrahedron ", tet_id, " (nodes ", id(0),
                  " ", id(1), " ", id(2), " ", id(3),
                  ") is inverted or has zero volume (validate the mesh with validate_mesh, which repairs orientation)");
    }
    for (int b = 0; b < 4; ++b) {
      const int j = mesh.tets(t, b);
      const auto& nb = adj[static_cast<std::size_t>(j)];
      for (int a = 0; a < 4; ++a) {
        const int i = mesh.tets(t, a);
        const int pos = static_cast<int>(std::lower_bound(nb.begin(), nb.end(), i) - nb.begin());
        for (int c = 0; c < 3; ++c) {
          double* col = value + col_start[static_cast<std::size_t>(3 * j + c)] + 3 * pos;
          for (int r = 0; r < 3; ++r) col[r] += ke(3 * a + r, 3 * b + c);
        }
      }
    }
  }
  return k;
}

Eigen::SparseMatrix<double> free_stiffness(const Eigen::SparseMatrix<double>& k, const FixedSet& fixed) {
  const auto& index = fixed.free_index();
  const int nf = fixed.free_dof_count();
  Eigen::SparseMatrix<double> out(nf, nf);
  std::vector<int> count(static_cast<std::size_t>(nf), 0);
  for (int jf = 0; jf < nf; ++jf) {
    const int j = fixed.free_dofs()[static_cast<std::size_t>(jf)];
    for (Eigen::SparseMatrix<double>::InnerIterator it(k, j); it; ++it)
      if (index[static_cast<std::size_t>(it.row())] >= 0) ++count[static_cast<std::size_t>(jf)];
  }
  out.reserve(count);
  for (int jf = 0; jf < nf; ++jf) {
    const int j = fixed.free_dofs()[static_cast<std::size_t>(jf)];
    for (Eigen::SparseMatrix<double>::InnerIterator it(k, j); it; ++it) {
      const int i = index[static_cast<std::size_t>(it.row())];
      if (i >= 0) out.insert(i, jf) = it.value();
    }
  }
  out.makeCompressed();
  return out;
}

TetInversion count_inverted_tets(const TetMesh& mesh, const Eigen::MatrixX3d& displacement) {
  if (displacement.rows() != mesh.nodes.rows())
    throw_error("count_inverted_tets: ", displacement.rows(), " displacement rows for ", mesh.nodes.rows(), " nodes");
  TetInversion out;
  for (Eigen::Index t = 0; t < mesh.tets.rows(); ++t) {
    Eigen::Matrix3d rest, deformed;
    for (int a = 0; a < 3; ++a) {
      const int i0 = mesh.tets(t, 0), ia = mesh.tets(t, a + 1);
      rest.col(a) = (mesh.nodes.row(ia) - mesh.nodes.row(i0)).transpose();
      deformed.col(a) = rest.col(a) + (displacement.row(ia) - displacement.row(i0)).transpose();
    }
    const double ratio = deformed.determinant() / rest.determinant();
    if (!(ratio > 0)) ++out.inverted;  // NaN counts: such a tet cannot be trusted
    if (out.worst_tet < 0 || !(ratio >= out.min_volume_ratio)) {
      out.worst_tet = static_cast<int>(t);
      out.min_volume_ratio = ratio;
    }
  }
  return out;
}

ElasticModel build_elastic_model(const TetMesh& mesh, const Material& material, const FixedSet& fixed,
                                 const std::string& where) {
  const std::string prefix = where.empty() ? std::string() : where + ": ";
  try {
    check_material(material);
  } catch (const Error& e) {
    throw Error(prefix + e.what());
  }
  check_rigid_modes_removed(mesh, fixed, where);
  ElasticModel model;
  model.mesh = &mesh;
  model.material = material;
  model.elements = element_materials(mesh, material, where);
  model.fixed = fixed;
  model.k = assemble_stiffness(mesh, model.elements);
  model.k_ff = free_stiffness(model.k, fixed);
  return model;
}

}  // namespace surgsim::fem
