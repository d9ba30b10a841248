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

// Inserts (n, w) into nodes/weights, kept in descending weight order with at most `capacity` entries; `out` counts
// the entries that did not fit (the new one or the one it pushed out).
void keep_largest(int n, double w, int capacity, int* nodes, double* weights, int& count, int& out) {
  int pos = count < capacity ? count : capacity;
  if (count >= capacity) {
    ++out;
    if (!(w > weights[capacity - 1])) return;
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

// Scales weights[0..count) to sum 1 (when their sum is > 0); returns the sum before.
double normalize(double* weights, int count) {
  double sum = 0;
  for (int i = 0; i < count; ++i) sum += weights[i];
  if (sum > 0)
    for (int i = 0; i < count; ++i) weights[i] /= sum;
  return sum;
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
  corners_.resize(3 * nf);
  for (std::size_t f = 0; f < nf; ++f) {
    const auto fi = static_cast<Eigen::Index>(f);
    const Eigen::Vector3d a = node_at(mesh, surface.tris(fi, 0)), b = node_at(mesh, surface.tris(fi, 1)),
                          c = node_at(mesh, surface.tris(fi, 2));
    corners_[3 * f] = a;
    corners_[3 * f + 1] = b;
    corners_[3 * f + 2] = c;
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
  // Edge adjacency for the footprint's walk: the triangle across the edge opposite each vertex.
  adjacent_.assign(3 * nf, -1);
  {
    struct Edge {
      int a, b, f, v;
    };
    std::vector<Edge> edges;
    edges.reserve(3 * nf);
    for (std::size_t f = 0; f < nf; ++f)
      for (int v = 0; v < 3; ++v) {
        const int a = surface.tris(static_cast<Eigen::Index>(f), (v + 1) % 3);
        const int b = surface.tris(static_cast<Eigen::Index>(f), (v + 2) % 3);
        edges.push_back({std::min(a, b), std::max(a, b), static_cast<int>(f), v});
      }
    std::sort(edges.begin(), edges.end(), [](const Edge& x, const Edge& y) {
      return x.a != y.a ? x.a < y.a : x.b != y.b ? x.b < y.b : x.f < y.f;
    });
    for (std::size_t i = 0; i < edges.size();) {
      std::size_t j = i + 1;
      while (j < edges.size() && edges[j].a == edges[i].a && edges[j].b == edges[i].b) ++j;
      if (j - i == 2) {  // a manifold edge; a non-manifold one (three or more triangles) gets no neighbour
        adjacent_[static_cast<std::size_t>(3 * edges[i].f + edges[i].v)] = edges[i + 1].f;
        adjacent_[static_cast<std::size_t>(3 * edges[i + 1].f + edges[i + 1].v)] = edges[i].f;
      }
      i = j;
    }
  }
  // The footprint's radial quadrature: 4-point Gauss-Legendre in u = sqrt(1 - (rho/a)^2) on [0, 1], in which the
  // flat punch's pressure integrates with a constant density (each ring carries its Gauss weight of the load).
  {
    const double x[kFootprintRings] = {-0.8611363115940526, -0.3399810435848563, 0.3399810435848563,
                                       0.8611363115940526};
    const double w[kFootprintRings] = {0.3478548451374538, 0.6521451548625461, 0.6521451548625461, 0.3478548451374538};
    for (int r = 0; r < kFootprintRings; ++r) {
      const double u = 0.5 * (x[r] + 1);
      ring_rho_[static_cast<std::size_t>(r)] = std::sqrt(1 - u * u);
      ring_weight_[static_cast<std::size_t>(r)] = 0.5 * w[r];
      for (int k = 0; k < kFootprintAngles; ++k) {
        constexpr double kTwoPi = 6.283185307179586;
        const double theta = kTwoPi * (k + 0.5 * (r % 2)) / kFootprintAngles;  // rings staggered
        angle_cos_[static_cast<std::size_t>(r * kFootprintAngles + k)] = std::cos(theta);
        angle_sin_[static_cast<std::size_t>(r * kFootprintAngles + k)] = std::sin(theta);
      }
    }
  }
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
  const auto fc = static_cast<std::size_t>(3 * f);
  r.point = closest_point_triangle(p, corners_[fc], corners_[fc + 1], corners_[fc + 2], bary);
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
    keep_largest(n, w, capacity, nodes, weights, count, out);  // ties: candidate order, deterministic
  }
  normalize(weights, count);
  if (dropped) *dropped = out;
  if (fixed) *fixed = stuck;
  return count;
}

int ContactSurface::locate(const Eigen::Vector3d& q, const Eigen::Vector3d& t1, const Eigen::Vector3d& t2,
                           const Eigen::Vector3d& normal, int f, Eigen::Vector3d& bary) const noexcept {
  for (int step = 0; step < kMaxWalk && f >= 0; ++step) {
    // Only faces within about 78 degrees of the pressing direction: the projection along it is well posed.
    if (!(face_normals_[static_cast<std::size_t>(f)].dot(normal) > 0.2)) return -1;
    Eigen::Vector2d p[3];
    for (int v = 0; v < 3; ++v) {
      const Eigen::Vector3d d = corners_[static_cast<std::size_t>(3 * f + v)] - q;
      p[v] = Eigen::Vector2d(d.dot(t1), d.dot(t2));
    }
    const auto cross = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); };
    const double area = cross(p[1] - p[0], p[2] - p[0]);
    if (!(area > 0)) return -1;
    bary = Eigen::Vector3d(cross(p[1], p[2]), cross(p[2], p[0]), cross(p[0], p[1])) / area;
    int worst = 0;
    for (int v = 1; v < 3; ++v)
      if (bary[v] < bary[worst]) worst = v;
    if (bary[worst] >= -1e-12) return f;
    f = adjacent_[static_cast<std::size_t>(3 * f + worst)];
  }
  return -1;
}

int ContactSurface::footprint(const Eigen::Vector3d& c, int triangle, const Eigen::Vector3d& normal, double a,
                              int capacity, int* nodes, double* weights, int* dropped, int* fixed,
                              int* walk) const noexcept {
  if (dropped) *dropped = 0;
  if (fixed) *fixed = 0;
  if (triangle < 0 || triangle >= surface_.tris.rows() || capacity <= 0 || !(a > 0)) return 0;
  Eigen::Vector3d t1 = std::abs(normal.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  t1 = (t1 - t1.dot(normal) * normal).normalized();
  const Eigen::Vector3d t2 = normal.cross(t1);
  constexpr int kMax = 3 * kFootprintRings * kFootprintAngles;
  std::array<int, kMax> cand_node{};
  std::array<double, kMax> cand_weight{};
  int cand = 0;
  int f = triangle;
  for (int r = 0; r < kFootprintRings; ++r) {
    const double rho = a * ring_rho_[static_cast<std::size_t>(r)];
    const double share = ring_weight_[static_cast<std::size_t>(r)] / kFootprintAngles;
    for (int k = 0; k < kFootprintAngles; ++k) {
      const auto ak = static_cast<std::size_t>(r * kFootprintAngles + k);
      const Eigen::Vector3d q = c + rho * (angle_cos_[ak] * t1 + angle_sin_[ak] * t2);
      Eigen::Vector3d bary;
      const int hint = walk != nullptr ? walk[ak] : -1;
      int g = locate(q, t1, t2, normal, hint >= 0 && hint < surface_.tris.rows() ? hint : f, bary);
      if (g < 0 && hint >= 0 && hint != f) g = locate(q, t1, t2, normal, f, bary);
      if (walk != nullptr) walk[ak] = g;
      if (g < 0) continue;
      f = g;
      for (int v = 0; v < 3; ++v) {
        const int node = surface_.tris(g, v);
        const double w = share * std::max(bary[v], 0.0);
        int i = 0;
        while (i < cand && cand_node[static_cast<std::size_t>(i)] != node) ++i;
        if (i == cand) {
          cand_node[static_cast<std::size_t>(cand)] = node;
          cand_weight[static_cast<std::size_t>(cand++)] = 0;
        }
        cand_weight[static_cast<std::size_t>(i)] += w;
      }
    }
  }
  int count = 0, out = 0, stuck = 0;
  for (int i = 0; i < cand; ++i) {
    const int n = cand_node[static_cast<std::size_t>(i)];
    const double w = cand_weight[static_cast<std::size_t>(i)];
    if (!(w > 0)) continue;
    if (free_[static_cast<std::size_t>(n)] == 0) {
      ++stuck;
      continue;
    }
    keep_largest(n, w, capacity, nodes, weights, count, out);  // ties: first found
  }
  const double sum = normalize(weights, count);
  if (dropped) *dropped = out;
  if (fixed) *fixed = stuck;
  return sum > 0 ? count : 0;
}

Eigen::Vector3d ContactSurface::patch_normal(const int* nodes, const double* weights, int count) const noexcept {
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  for (int i = 0; i < count; ++i) n += weights[i] * vertex_normal(nodes[i]);
  const double len = n.norm();
  return len > 1e-12 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::UnitZ();
}

}  // namespace surgsim::contact
