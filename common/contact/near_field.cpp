#include "contact/near_field.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::contact {

namespace {
constexpr double kPi = 3.14159265358979323846;

// A node's hat function normalized to unit integral, as weighted points (sub-triangle centroids) with the radius
// of the disc of each sub-triangle's area.
struct Cloud {
  std::vector<Eigen::Vector3d> x;
  std::vector<double> w, r;
  void clear() {
    x.clear();
    w.clear();
    r.clear();
  }
};

void hat_cloud(const TetMesh& mesh, const SurfaceMesh& surface, const NodeTriangles& nt, int node, Cloud& out) {
  out.clear();
  const int n = NearField::kSplit;
  double area = 0;
  const auto sn = static_cast<std::size_t>(node);
  for (int k = nt.start[sn]; k < nt.start[sn + 1]; ++k) {
    const int f = nt.list[static_cast<std::size_t>(k)];
    int v = 0;
    while (v < 3 && surface.tris(f, v) != node) ++v;
    const Eigen::Vector3d p0 = mesh.nodes.row(surface.tris(f, 0)).transpose();
    const Eigen::Vector3d p1 = mesh.nodes.row(surface.tris(f, 1)).transpose();
    const Eigen::Vector3d p2 = mesh.nodes.row(surface.tris(f, 2)).transpose();
    const double a = 0.5 * (p1 - p0).cross(p2 - p0).norm();
    area += a / 3;
    const double sub = a / (n * n);
    const double radius = std::sqrt(sub / kPi);
    const auto add = [&](double b1, double b2) {
      const Eigen::Vector3d b(1 - b1 - b2, b1, b2);
      out.x.push_back(b[0] * p0 + b[1] * p1 + b[2] * p2);
      out.w.push_back(b[v] * sub);
      out.r.push_back(radius);
    };
    for (int i = 0; i < n; ++i)
      for (int j = 0; i + j < n; ++j) {
        add((i + 1.0 / 3) / n, (j + 1.0 / 3) / n);                     // upward sub-triangle
        if (i + j < n - 1) add((i + 2.0 / 3) / n, (j + 2.0 / 3) / n);  // downward
      }
  }
  if (area > 0)
    for (double& w : out.w) w /= area;
}

double energy(const Cloud& a, const Cloud& b) {
  double s = 0;
  for (std::size_t i = 0; i < a.x.size(); ++i)
    for (std::size_t j = 0; j < b.x.size(); ++j) {
      const double d = (a.x[i] - b.x[j]).norm();
      // The same sub-triangle (in one cloud, or a triangle both hats share): the mean 1/|x - y| over a disc of equal
      // area, 16 / (3 pi r). Others: the mean over two discs to second order, 1/d + (r_a^2 + r_b^2) / (8 d^3) (the
      // plane Laplacian of 1/|x| is 1/|x|^3; a disc's second moment is r^2/4 per axis).
      s += a.w[i] * b.w[j] *
           (d < 1e-9 * a.r[i] ? 16.0 / (3 * kPi * a.r[i])
                              : 1.0 / d + (a.r[i] * a.r[i] + b.r[j] * b.r[j]) / (8 * d * d * d));
    }
  return s;
}
}  // namespace

NearField::NearField(const TetMesh& mesh, const SurfaceMesh& surface, const fem::Material& material,
                     const compliance::Tensors* tensors)
    : mesh_(mesh) {
  const double e = material.young_modulus, nu = material.poisson_ratio;
  if (!(e > 0) || !std::isfinite(e) || !(nu >= 0 && nu < 0.5))
    throw_error("near field: material out of range (young_modulus ", e, " Pa, poisson_ratio ", nu, ")");
  kernel_ = (1 - nu * nu) / (kPi * e);
  tangent_ratio_ = (2 - nu) / (2 * (1 - nu));
  const auto nv = static_cast<std::size_t>(mesh.nodes.rows());
  const NodeTriangles nt = node_triangles(surface, static_cast<int>(nv));
  self_.assign(nv, 0.0);
  // Neighbours: nodes sharing a surface triangle.
  std::vector<std::vector<int>> nb(nv);
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f)
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        if (a != b) nb[static_cast<std::size_t>(surface.tris(f, a))].push_back(surface.tris(f, b));
  start_.assign(nv + 1, 0);
  for (std::size_t i = 0; i < nv; ++i) {
    std::sort(nb[i].begin(), nb[i].end());
    nb[i].erase(std::unique(nb[i].begin(), nb[i].end()), nb[i].end());
    start_[i + 1] = start_[i] + static_cast<int>(nb[i].size());
  }
  other_.resize(static_cast<std::size_t>(start_[nv]));
  value_.assign(other_.size(), 0.0);
  std::vector<Cloud> clouds(nv);
  for (int node : surface.nodes) hat_cloud(mesh, surface, nt, node, clouds[static_cast<std::size_t>(node)]);
  for (int node : surface.nodes) {
    const auto i = static_cast<std::size_t>(node);
    self_[i] = energy(clouds[i], clouds[i]);
    for (std::size_t k = 0; k < nb[i].size(); ++k) {
      const int j = nb[i][k];
      const auto at = static_cast<std::size_t>(start_[i]) + k;
      other_[at] = j;
      if (j < node) {  // computed once per pair: copy the value stored under j
        const auto sj = static_cast<std::size_t>(j);
        for (int m = start_[sj]; m < start_[sj + 1]; ++m)
          if (other_[static_cast<std::size_t>(m)] == node) value_[at] = value_[static_cast<std::size_t>(m)];
      } else {
        value_[at] = energy(clouds[i], clouds[static_cast<std::size_t>(j)]);
      }
    }
  }
  // The mesh's own local compliance and its smooth part (normal components along the area-weighted vertex normals).
  self_local_.assign(nv, 0.0);
  local_.assign(value_.size(), 0.0);
  smooth_.assign(nv, 0.0);
  for (std::size_t i = 0; i < nv; ++i) self_local_[i] = kernel_ * self_[i];
  for (std::size_t k = 0; k < value_.size(); ++k) local_[k] = kernel_ * value_[k];
  const compliance::TensorBlock* block = tensors != nullptr ? tensors->find("haptic") : nullptr;
  if (block == nullptr) return;
  std::vector<Eigen::Vector3d> normal(nv, Eigen::Vector3d::Zero());
  std::vector<double> area(nv, 0.0);
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f) {
    const Eigen::Vector3d a = mesh.nodes.row(surface.tris(f, 0)).transpose();
    const Eigen::Vector3d n2 = (Eigen::Vector3d(mesh.nodes.row(surface.tris(f, 1)).transpose()) - a)
                                   .cross(Eigen::Vector3d(mesh.nodes.row(surface.tris(f, 2)).transpose()) - a);
    for (int v = 0; v < 3; ++v) {
      normal[static_cast<std::size_t>(surface.tris(f, v))] += n2;
      area[static_cast<std::size_t>(surface.tris(f, v))] += n2.norm() / 6;
    }
  }
  for (auto& n : normal)
    if (n.norm() > 0) n.normalize();
  const auto has = [&](int node) {
    const auto sn = static_cast<std::size_t>(node);
    return block->row_of_node[sn] >= 0 && tensors->column_of_node[sn] >= 0;
  };
  // Normal compliance of a pair, symmetrized: (n_i^T G_ij n_j + n_j^T G_ji n_i) / 2.
  const auto g = [&](int i, int j) {
    const auto si = static_cast<std::size_t>(i), sj = static_cast<std::size_t>(j);
    const double ij = normal[si].dot(block->block3(block->row_of_node[si], tensors->column_of_node[sj]) * normal[sj]);
    const double ji = normal[sj].dot(block->block3(block->row_of_node[sj], tensors->column_of_node[si]) * normal[si]);
    return 0.5 * (ij + ji);
  };
  std::vector<std::uint8_t> ok(nv, 0);
  for (int node : surface.nodes) {
    if (!has(node)) continue;
    const auto i = static_cast<std::size_t>(node);
    double num = area[i] * (g(node, node) - kernel_ * self_[i]), den = area[i];
    for (int k = start_[i]; k < start_[i + 1]; ++k) {
      const int j = other_[static_cast<std::size_t>(k)];
      if (!has(j)) continue;
      num += area[static_cast<std::size_t>(j)] * (g(node, j) - kernel_ * value_[static_cast<std::size_t>(k)]);
      den += area[static_cast<std::size_t>(j)];
    }
    if (!(den > 0)) continue;
    smooth_[i] = num / den;
    ok[i] = 1;
  }
  for (int node : surface.nodes) {
    const auto i = static_cast<std::size_t>(node);
    if (!ok[i]) continue;
    self_local_[i] = g(node, node) - smooth_[i];
    for (int k = start_[i]; k < start_[i + 1]; ++k) {
      const int j = other_[static_cast<std::size_t>(k)];
      if (ok[static_cast<std::size_t>(j)])
        local_[static_cast<std::size_t>(k)] = g(node, j) - 0.5 * (smooth_[i] + smooth_[static_cast<std::size_t>(j)]);
    }
  }
}

double NearField::interaction(int i, int j) const noexcept {
  const auto si = static_cast<std::size_t>(i);
  if (i == j) return self_[si];
  for (int k = start_[si]; k < start_[si + 1]; ++k)
    if (other_[static_cast<std::size_t>(k)] == j) return value_[static_cast<std::size_t>(k)];
  const double d = (mesh_.nodes.row(i) - mesh_.nodes.row(j)).norm();
  return d > 0 ? 1.0 / d : 0.0;
}

double NearField::local(int i, int j) const noexcept {
  const auto si = static_cast<std::size_t>(i);
  if (i == j) return self_local_[si];
  for (int k = start_[si]; k < start_[si + 1]; ++k)
    if (other_[static_cast<std::size_t>(k)] == j) return local_[static_cast<std::size_t>(k)];
  const double d = (mesh_.nodes.row(i) - mesh_.nodes.row(j)).norm();
  return d > 0 ? kernel_ / d : 0.0;
}

double NearField::normal(const int* nodes, const double* weights, int count, double a) const noexcept {
  if (!(a > 0) || count <= 0) return 0.0;
  double sum = 0;
  for (int p = 0; p < count; ++p) {
    sum += weights[p] * weights[p] * self_local_[static_cast<std::size_t>(nodes[p])];
    for (int q = 0; q < p; ++q) sum += 2 * weights[p] * weights[q] * local(nodes[p], nodes[q]);
  }
  const double d = kernel_ * kPi / (2 * a) - sum;
  return std::isfinite(d) && d > 0 ? d : 0.0;
}

}  // namespace surgsim::contact
