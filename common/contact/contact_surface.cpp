#include "contact/contact_surface.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "mesh/geometry.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::contact {

namespace {
Eigen::Vector3d node_at(const TetMesh& mesh, int n) { return mesh.nodes.row(n).transpose(); }

// Normal gate: 1 when the node's normal is within about 40 degrees of the contact's, 0 beyond about 75, C1 between.
double gate(double cosine) {
  const double t = std::clamp((cosine - 0.25) / 0.5, 0.0, 1.0);
  return t * t * (3 - 2 * t);
}
}  // namespace

double ContactSurface::mean_edge(const TetMesh& mesh, const SurfaceMesh& surface) {
  double sum = 0;
  long count = 0;
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f)
    for (int e = 0; e < 3; ++e) {
      sum += (node_at(mesh, surface.tris(f, e)) - node_at(mesh, surface.tris(f, (e + 1) % 3))).norm();
      ++count;
    }
  return count > 0 ? sum / static_cast<double>(count) : 0.0;
}

ContactSurface::ContactSurface(const TetMesh& mesh, const SurfaceMesh& surface,
                               const std::vector<std::uint8_t>& free_node, double radius)
    : mesh_(mesh), surface_(surface), radius_(radius), free_(free_node) {
  if (surface.tris.rows() == 0) throw_error("contact surface: the organ has no surface triangles");
  if (!(radius > 0) || !std::isfinite(radius)) throw_error("contact surface: tip radius must be > 0, got ", radius);
  const auto nv = static_cast<std::size_t>(mesh.nodes.rows());
  if (free_.size() != nv)
    throw_error("contact surface: free-node mask has ", free_.size(), " entries for ", nv, " nodes");
  const auto nf = static_cast<std::size_t>(surface.tris.rows());
  vertex_normals_.assign(nv, Eigen::Vector3d::Zero());
  face_normals_.resize(nf);
  for (std::size_t f = 0; f < nf; ++f) {
    const auto fi = static_cast<Eigen::Index>(f);
    const Eigen::Vector3d a = node_at(mesh, surface.tris(fi, 0)), b = node_at(mesh, surface.tris(fi, 1)),
                          c = node_at(mesh, surface.tris(fi, 2));
    const Eigen::Vector3d n2 = (b - a).cross(c - a);  // 2 x area, outward
    const double len = n2.norm();
    face_normals_[f] = len > 0 ? Eigen::Vector3d(n2 / len) : Eigen::Vector3d::UnitZ();
    for (int v = 0; v < 3; ++v) {
      vertex_normals_[static_cast<std::size_t>(surface.tris(fi, v))] += n2;  // area weighted
    }
  }
  for (auto& n : vertex_normals_) {
    const double len = n.norm();
    if (len > 0) n /= len;
  }
  node_tris_ = node_triangles(surface, static_cast<int>(nv));
  // Candidate patch nodes per triangle: surface nodes within r + circumradius of the centroid (brute force, once).
  cand_start_.assign(nf + 1, 0);
  for (std::size_t f = 0; f < nf; ++f) {
    const auto fi = static_cast<Eigen::Index>(f);
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int v = 0; v < 3; ++v) centroid += node_at(mesh, surface.tris(fi, v)) / 3.0;
    double reach = 0;
    for (int v = 0; v < 3; ++v) reach = std::max(reach, (node_at(mesh, surface.tris(fi, v)) - centroid).norm());
    reach += radius;
    for (int n : surface.nodes)
      if ((node_at(mesh, n) - centroid).squaredNorm() < reach * reach) cand_nodes_.push_back(n);
    cand_start_[f + 1] = static_cast<int>(cand_nodes_.size());
  }
}

RestPoint ContactSurface::on_triangle(const Eigen::Vector3d& p, int f) const noexcept {
  RestPoint r;
  if (f < 0 || f >= surface_.tris.rows()) return r;
  const int ia = surface_.tris(f, 0), ib = surface_.tris(f, 1), ic = surface_.tris(f, 2);
  Eigen::Vector3d bary;
  r.point = closest_point_triangle(p, node_at(mesh_, ia), node_at(mesh_, ib), node_at(mesh_, ic), bary);
  r.found = true;
  r.triangle = f;
  r.bary = bary;
  r.distance = (p - r.point).norm();
  r.face_normal = face_normals_[static_cast<std::size_t>(f)];
  const Eigen::Vector3d n = bary[0] * vertex_normal(ia) + bary[1] * vertex_normal(ib) + bary[2] * vertex_normal(ic);
  const double len = n.norm();
  r.normal = len > 1e-12 ? Eigen::Vector3d(n / len) : r.face_normal;
  return r;
}

RestPoint ContactSurface::closest_local(const Eigen::Vector3d& p, int start,
                                        const Eigen::Vector3d* facing) const noexcept {
  RestPoint best = on_triangle(p, start);
  if (!best.found) return best;
  for (int step = 0; step < kMaxWalk; ++step) {
    const int current = best.triangle;
    for (int v = 0; v < 3; ++v) {
      const auto n = static_cast<std::size_t>(surface_.tris(current, v));
      for (int k = node_tris_.start[n]; k < node_tris_.start[n + 1]; ++k) {
        const int f = node_tris_.list[static_cast<std::size_t>(k)];
        if (f == best.triangle) continue;
        if (facing != nullptr && !(face_normals_[static_cast<std::size_t>(f)].dot(*facing) > 0.5)) continue;
        const RestPoint r = on_triangle(p, f);
        // Strictly closer (ties keep the current triangle: no cycling between triangles sharing the closest point).
        if (r.distance < best.distance - 1e-12) best = r;
      }
    }
    if (best.triangle == current) break;
  }
  // On an edge or a vertex the closest point is shared: its interpolated normal is the same from either side, but
  // the face normal is the current triangle's.
  return best;
}

int ContactSurface::patch(const Eigen::Vector3d& c, int triangle, const Eigen::Vector3d& normal, int capacity,
                          int* nodes, double* weights, int* dropped, int* fixed) const noexcept {
  int count = 0, out = 0, stuck = 0;
  if (triangle < 0 || triangle >= surface_.tris.rows() || capacity <= 0) {
    if (dropped) *dropped = 0;
    if (fixed) *fixed = 0;
    return 0;
  }
  const double inv_r = 1.0 / radius_;
  for (int k = cand_start_[static_cast<std::size_t>(triangle)]; k < cand_start_[static_cast<std::size_t>(triangle) + 1];
       ++k) {
    const int n = cand_nodes_[static_cast<std::size_t>(k)];
    const double q = (node_at(mesh_, n) - c).norm() * inv_r;
    if (q >= 1) continue;
    const double w = std::pow(1 - q, 4) * (4 * q + 1) * gate(vertex_normal(n).dot(normal));
    if (!(w > 0)) continue;
    if (free_[static_cast<std::size_t>(n)] == 0) {
      ++stuck;
      continue;
    }
    // Keep the `capacity` largest weights, in descending order (ties: candidate order, deterministic).
    int pos = count < capacity ? count : capacity;
    if (count >= capacity) {
      ++out;
      if (!(w > weights[capacity - 1])) continue;
    }
    while (pos > 0 && weights[pos - 1] < w) {
      if (pos < capacity) {
        weights[pos] = weights[pos - 1];
        nodes[pos] = nodes[pos - 1];
      }
      --pos;
    }
    weights[pos] = w;
    nodes[pos] = n;
    if (count < capacity) ++count;
  }
  double sum = 0;
  for (int i = 0; i < count; ++i) sum += weights[i];
  if (sum > 0)
    for (int i = 0; i < count; ++i) weights[i] /= sum;
  if (dropped) *dropped = out;
  if (fixed) *fixed = stuck;
  return count;
}

Eigen::Vector3d ContactSurface::patch_normal(const int* nodes, const double* weights, int count) const noexcept {
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  for (int i = 0; i < count; ++i) n += weights[i] * vertex_normal(nodes[i]);
  const double len = n.norm();
  return len > 1e-12 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::UnitZ();
}

}  // namespace surgsim::contact
