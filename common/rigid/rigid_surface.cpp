// RigidSurface: validation at build (orientation, manifold edges, finite coordinates, degenerate triangles), the
// pseudo-normals that give the closest point's side, the uniform grid, and the allocation-free queries.
#include "rigid/rigid_surface.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>

#include "core/error.h"
#include "mesh/geometry.h"

namespace surgsim::rigid {

namespace {

// A triangle whose doubled area is below this fraction of its longest edge squared is degenerate (a sliver whose
// normal rounding cannot give).
constexpr double kDegenerate = 1e-10;
// At most this many grid cells (memory: 4 bytes each, plus the triangle lists).
constexpr double kMaxCells = 4e6;

}  // namespace

RigidSurface::RigidSurface(const mesh::TriSurface& surface, bool cavity, const std::string& where)
    : surface_(surface), cavity_(cavity), where_(where) {
  const int nv = static_cast<int>(surface.vertices.rows());
  const int nf = static_cast<int>(surface.tris.rows());
  if (nf == 0)
    core::throw_error(where,
                      ": the rigid surface has no triangles (give it a closed or open triangle "
                      "surface, counter-clockwise seen from the free side)");
  for (int v = 0; v < nv; ++v) {
    if (!surface.vertices.row(v).allFinite())
      core::throw_error(where, ": vertex ", v, " has a coordinate that is not finite (", surface.vertices(v, 0), " ",
                        surface.vertices(v, 1), " ", surface.vertices(v, 2), "): fix or remove it");
    vertices_.emplace_back(surface.vertices.row(v).transpose());
  }
  tris_.resize(static_cast<std::size_t>(nf));
  for (int f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) {
      const int v = surface.tris(f, k);
      if (v < 0 || v >= nv)
        core::throw_error(where, ": triangle ", f, " uses vertex ", v, ", but there are ", nv, " vertices");
    }
    // Stored counter-clockwise seen from the free side: a cavity's triangles are turned over.
    Tri& t = tris_[static_cast<std::size_t>(f)];
    t.v[0] = surface.tris(f, 0);
    t.v[1] = cavity ? surface.tris(f, 2) : surface.tris(f, 1);
    t.v[2] = cavity ? surface.tris(f, 1) : surface.tris(f, 2);
    const Eigen::Vector3d &a = vertices_[t.v[0]], &b = vertices_[t.v[1]], &c = vertices_[t.v[2]];
    const Eigen::Vector3d n = (b - a).cross(c - a);
    const double longest = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
    if (!(n.norm() > kDegenerate * longest))
      core::throw_error(where, ": triangle ", f, " (vertices ", surface.tris(f, 0), " ", surface.tris(f, 1), " ",
                        surface.tris(f, 2), ") is degenerate (area ", 0.5 * n.norm(),
                        " m^2): remove it or merge its vertices");
    face_normal_.push_back(n.normalized());
  }

  // Edges: each used at most twice, and then in opposite directions (consistent orientation), else the surface has
  // no side to push out to.
  struct HalfEdge {
    int lo, hi, face, local;  // undirected edge lo < hi; the triangle and its edge (v[local] -> v[local + 1])
    bool forward;             // lo -> hi in the triangle
  };
  std::vector<HalfEdge> half;
  half.reserve(static_cast<std::size_t>(3 * nf));
  for (int f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) {
      const int a = surface.tris(f, k), b = surface.tris(f, (k + 1) % 3);
      // The local edge in the stored (free side) order: a cavity's edge k of the input is edge (3 - k) % 3 reversed.
      const int local = cavity ? (2 - k + 3) % 3 : k;
      half.push_back({std::min(a, b), std::max(a, b), f, local, a < b});
    }
  }
  std::sort(half.begin(), half.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return std::tie(x.lo, x.hi, x.face) < std::tie(y.lo, y.hi, y.face);
  });
  edge_normal_.assign(static_cast<std::size_t>(3 * nf), Eigen::Vector3d::Zero());
  neighbour_.assign(static_cast<std::size_t>(3 * nf), -1);
  for (std::size_t i = 0; i < half.size();) {
    std::size_t j = i;
    while (j < half.size() && half[j].lo == half[i].lo && half[j].hi == half[i].hi) ++j;
    const HalfEdge& h = half[i];
    if (j - i > 2)
      core::throw_error(where, ": edge ", h.lo, "-", h.hi, " is shared by ", j - i, " triangles (", half[i].face, ", ",
                        half[i + 1].face, ", ", half[i + 2].face,
                        "): a non-manifold edge has no side to push out to; split the surface into separate organs");
    if (j - i == 2 && half[i].forward == half[i + 1].forward)
      core::throw_error(where, ": edge ", h.lo, "-", h.hi, " is used twice in the same direction (triangles ",
                        half[i].face, " and ", half[i + 1].face,
                        "): the surface is not consistently oriented, so it has no side to push out to; reverse the "
                        "vertex order of the triangles facing the wrong way");
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    for (std::size_t k = i; k < j; ++k) n += face_normal_[static_cast<std::size_t>(half[k].face)];
    n.normalize();
    for (std::size_t k = i; k < j; ++k) edge_normal_[static_cast<std::size_t>(3 * half[k].face + half[k].local)] = n;
    if (j - i == 2) {
      neighbour_[static_cast<std::size_t>(3 * half[i].face + half[i].local)] = half[i + 1].face;
      neighbour_[static_cast<std::size_t>(3 * half[i + 1].face + half[i + 1].local)] = half[i].face;
    }
    i = j;
  }

  vertex_start_.assign(vertices_.size() + 1, 0);
  for (const Tri& t : tris_)
    for (int k = 0; k < 3; ++k) ++vertex_start_[static_cast<std::size_t>(t.v[k]) + 1];
  for (std::size_t v = 0; v < vertices_.size(); ++v) vertex_start_[v + 1] += vertex_start_[v];
  vertex_tris_.assign(static_cast<std::size_t>(vertex_start_.back()), 0);
  {
    std::vector<int> fill(vertex_start_.begin(), vertex_start_.end() - 1);
    for (int f = 0; f < nf; ++f)
      for (int k = 0; k < 3; ++k) vertex_tris_[static_cast<std::size_t>(fill[tris_[f].v[k]]++)] = f;
  }

  vertex_normal_.assign(vertices_.size(), Eigen::Vector3d::Zero());
  for (int f = 0; f < nf; ++f) {
    const Tri& t = tris_[static_cast<std::size_t>(f)];
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& p = vertices_[t.v[k]];
      const Eigen::Vector3d e1 = (vertices_[t.v[(k + 1) % 3]] - p).normalized();
      const Eigen::Vector3d e2 = (vertices_[t.v[(k + 2) % 3]] - p).normalized();
      const double angle = std::acos(std::clamp(e1.dot(e2), -1.0, 1.0));
      vertex_normal_[t.v[k]] += angle * face_normal_[static_cast<std::size_t>(f)];
    }
  }
  for (Eigen::Vector3d& n : vertex_normal_)
    if (n.squaredNorm() > 0) n.normalize();

  bounds_.setEmpty();
  for (const Tri& t : tris_)
    for (int k = 0; k < 3; ++k) bounds_.extend(vertices_[t.v[k]]);
  build_grid();
}

void RigidSurface::build_grid() {
  // Cells about the mean edge length, or larger so that there are about two cells per triangle (a large flat organ
  // with few triangles), within kMaxCells.
  double edges = 0;
  for (const Tri& t : tris_)
    for (int k = 0; k < 3; ++k) edges += (vertices_[t.v[(k + 1) % 3]] - vertices_[t.v[k]]).norm();
  const double mean_edge = edges / (3.0 * static_cast<double>(tris_.size()));
  const Eigen::Vector3d extent = (bounds_.sizes().array() + 2 * mean_edge).matrix();
  cell_ = std::max(mean_edge, std::cbrt(extent.prod() / (2.0 * static_cast<double>(tris_.size()))));
  auto count = [&] { return (extent / cell_).array().ceil().max(1.0).eval(); };
  while (count().prod() > kMaxCells) cell_ *= 1.25;
  cells_ = count().cast<int>().matrix();
  grid_origin_ = (bounds_.min().array() - mean_edge).matrix();

  auto cell_range = [&](const Tri& t, Eigen::Vector3i& lo, Eigen::Vector3i& hi) {
    Eigen::AlignedBox3d box;
    for (int k = 0; k < 3; ++k) box.extend(vertices_[t.v[k]]);
    lo = ((box.min() - grid_origin_) / cell_).array().floor().cast<int>().max(0).min(cells_.array() - 1).matrix();
    hi = ((box.max() - grid_origin_) / cell_).array().floor().cast<int>().max(0).min(cells_.array() - 1).matrix();
  };
  const std::size_t n_cells = static_cast<std::size_t>(cells_.prod());
  cell_start_.assign(n_cells + 1, 0);
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<int> fill;
    if (pass == 1) {
      for (std::size_t c = 0; c < n_cells; ++c) cell_start_[c + 1] += cell_start_[c];
      cell_tris_.assign(static_cast<std::size_t>(cell_start_[n_cells]), 0);
      fill.assign(cell_start_.begin(), cell_start_.end() - 1);
    }
    for (int f = 0; f < triangle_count(); ++f) {
      Eigen::Vector3i lo, hi;
      cell_range(tris_[static_cast<std::size_t>(f)], lo, hi);
      for (int k = lo.z(); k <= hi.z(); ++k)
        for (int j = lo.y(); j <= hi.y(); ++j)
          for (int i = lo.x(); i <= hi.x(); ++i) {
            const std::size_t c = static_cast<std::size_t>(i + cells_.x() * (j + cells_.y() * k));
            if (pass == 0)
              ++cell_start_[c + 1];
            else
              cell_tris_[static_cast<std::size_t>(fill[c]++)] = f;
          }
    }
  }
}

template <typename F>
void RigidSurface::for_each_in_box(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, F&& f) const noexcept {
  if (!lo.allFinite() || !hi.allFinite()) return;
  // Cell indices computed in double and clamped before the cast (a far point would overflow an int).
  const Eigen::Array3d a = ((lo - grid_origin_) / cell_).array().floor();
  const Eigen::Array3d b = ((hi - grid_origin_) / cell_).array().floor();
  const Eigen::Array3d n = cells_.cast<double>().array();
  if ((b < 0).any() || (a >= n).any()) return;
  const Eigen::Array3i i0 = a.max(0.0).min(n - 1).cast<int>(), i1 = b.max(0.0).min(n - 1).cast<int>();
  for (int k = i0.z(); k <= i1.z(); ++k)
    for (int j = i0.y(); j <= i1.y(); ++j)
      for (int i = i0.x(); i <= i1.x(); ++i) {
        const std::size_t c = static_cast<std::size_t>(i + cells_.x() * (j + cells_.y() * k));
        for (int s = cell_start_[c]; s < cell_start_[c + 1]; ++s) f(cell_tris_[static_cast<std::size_t>(s)]);
      }
}

double RigidSurface::triangle_distance(const Eigen::Vector3d& p, int f) const noexcept {
  Eigen::Vector3d bary;
  return (p - closest_on(p, f, bary)).norm();
}

Eigen::Vector3d RigidSurface::closest_on(const Eigen::Vector3d& p, int f, Eigen::Vector3d& bary) const noexcept {
  const Tri& t = tris_[static_cast<std::size_t>(f)];
  return mesh::closest_point_triangle(p, vertices_[t.v[0]], vertices_[t.v[1]], vertices_[t.v[2]], bary);
}

template <typename F>
void RigidSurface::for_each_near(const Eigen::Vector3d& p, double max_distance, F&& f) const noexcept {
  const double max2 = max_distance * max_distance;
  const Eigen::Vector3d reach = Eigen::Vector3d::Constant(max_distance);
  for_each_in_box(p - reach, p + reach, [&](int tri) {
    Eigen::Vector3d bary;
    const Eigen::Vector3d q = closest_on(p, tri, bary);
    const double d2 = (p - q).squaredNorm();
    if (d2 <= max2) f(tri, q, bary, d2);
  });
}

ClosestPoint RigidSurface::closest_point(const Eigen::Vector3d& p, double max_distance) const noexcept {
  ClosestPoint out;
  double best = max_distance * max_distance;
  Eigen::Vector3d best_bary = Eigen::Vector3d::Zero();
  for_each_near(p, max_distance, [&](int f, const Eigen::Vector3d& q, const Eigen::Vector3d& bary, double d2) {
    // The nearest triangle; on a tie the lowest index (the same answer whatever the cell order).
    if (d2 < best || (d2 == best && (!out.found || f < out.triangle))) {
      best = d2;
      out.found = true;
      out.point = q;
      out.triangle = f;
      best_bary = bary;
    }
  });
  if (!out.found) return out;
  // The side from the pseudo-normal of the feature holding the point: the face's normal inside it, the two faces'
  // sum on an edge, the angle-weighted normal at a vertex (exact for a closed surface, Baerentzen and Aanaes 2005).
  const Tri& t = tris_[static_cast<std::size_t>(out.triangle)];
  out.corners = Eigen::Vector3i(t.v[0], t.v[1], t.v[2]);
  out.bary = best_bary;
  const int zeros = (best_bary.array() == 0).count();
  Eigen::Vector3d pseudo = face_normal_[static_cast<std::size_t>(out.triangle)];
  if (zeros == 2) {
    int k = 0;
    best_bary.maxCoeff(&k);
    pseudo = vertex_normal_[t.v[k]];
  } else if (zeros == 1) {
    int k = 0;
    best_bary.minCoeff(&k);
    pseudo = edge_normal_[static_cast<std::size_t>(3 * out.triangle + (k + 1) % 3)];
  }
  const Eigen::Vector3d offset = p - out.point;
  const double d = std::sqrt(best);
  const double side = offset.dot(pseudo) >= 0 ? 1.0 : -1.0;
  out.distance = side * d;
  out.normal = d > 0 ? Eigen::Vector3d(side * offset / d) : pseudo;
  return out;
}

bool RigidSurface::dominated(const Eigen::Vector3d& p, int f, const Eigen::Vector3d& bary, double d) const noexcept {
  const int zeros = (bary.array() == 0).count();
  if (zeros == 0) return false;  // inside the face
  if (zeros == 1) {              // on the edge opposite the zero: the triangle across it
    int k = 0;
    bary.minCoeff(&k);
    const int g = neighbour_[static_cast<std::size_t>(3 * f + (k + 1) % 3)];
    return g >= 0 && triangle_distance(p, g) < d;
  }
  int k = 0;  // on a vertex: every triangle around it
  bary.maxCoeff(&k);
  const int v = tris_[static_cast<std::size_t>(f)].v[k];
  for (int i = vertex_start_[static_cast<std::size_t>(v)]; i < vertex_start_[static_cast<std::size_t>(v) + 1]; ++i)
    if (triangle_distance(p, vertex_tris_[static_cast<std::size_t>(i)]) < d) return true;
  return false;
}

int RigidSurface::touching(const Eigen::Vector3d& p, double max_distance, Touch* out, int capacity) const noexcept {
  int n = 0;
  for_each_near(p, max_distance, [&](int f, const Eigen::Vector3d& q, const Eigen::Vector3d& bary, double d2) {
    const double d = std::sqrt(d2);
    if (dominated(p, f, bary, d)) return;
    const Eigen::Vector3d normal = d > 0 ? Eigen::Vector3d((p - q) / d) : face_normal_[static_cast<std::size_t>(f)];
    for (int i = 0; i < n; ++i) {
      if (normal.dot(out[i].normal) > 1 - 1e-10) {  // the same direction: keep the nearest (lowest index on a tie)
        if (d < out[i].distance || (d == out[i].distance && f < out[i].triangle)) out[i] = {q, normal, d, f};
        return;
      }
    }
    if (n < capacity) out[n++] = {q, normal, d, f};
  });
  return n;
}

namespace {
// A motion that closes in on a feature the sphere already touches (or on a face's plane) more slowly than this
// fraction of its length is tangent to it: sliding along a face, across the edges of coplanar triangles, is not a
// hit (rounding leaves the proxy a few 1e-18 m inside a tilted plane, and the slide then stopped at every edge).
constexpr double kGrazing = 1e-6;
}  // namespace

SegmentHit RigidSurface::segment_hit(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double radius) const noexcept {
  SegmentHit out;
  const Eigen::Vector3d d = b - a;
  const double dd = d.squaredNorm();
  if (!(dd > 0)) return out;
  const double r2 = radius * radius;
  double best = std::numeric_limits<double>::infinity();
  int best_tri = -1;
  // Entry of the ray a + t d into a sphere of radius `radius` about v (t >= 0), infinity if none in [0, 1].
  auto vertex_entry = [&](const Eigen::Vector3d& v) {
    const Eigen::Vector3d m = a - v;
    const double bh = m.dot(d), c = m.squaredNorm() - r2;
    if (c <= 0) return bh < -kGrazing * m.norm() * std::sqrt(dd) ? 0.0 : std::numeric_limits<double>::infinity();
    const double disc = bh * bh - dd * c;
    if (bh >= 0 || disc < 0) return std::numeric_limits<double>::infinity();
    const double t = (-bh - std::sqrt(disc)) / dd;
    // Grazing entry (the motion tangent to the sphere where it enters): not a contact.
    const Eigen::Vector3d nrm = m + t * d;
    return -nrm.dot(d) < kGrazing * nrm.norm() * std::sqrt(dd) ? std::numeric_limits<double>::infinity() : t;
  };
  // Entry into the cylinder of radius `radius` about the edge e0-e1 (within its length; the ends are the
  // vertices' spheres). Ericson, Real-Time Collision Detection 5.3.7.
  auto edge_entry = [&](const Eigen::Vector3d& e0, const Eigen::Vector3d& e1) {
    const Eigen::Vector3d e = e1 - e0, m = a - e0;
    const double ee = e.squaredNorm(), md = m.dot(e), de = d.dot(e);
    const double qa = ee * dd - de * de;
    if (qa <= 1e-20 * ee * dd) return std::numeric_limits<double>::infinity();  // along the edge: the ends decide
    const double qb = ee * m.dot(d) - md * de, qc = ee * (m.squaredNorm() - r2) - md * md;
    double t;
    if (qc <= 0) {  // already within the radius of the edge's line: a hit only when closing in on it
      const double m_perp = std::sqrt(std::max(0.0, m.squaredNorm() - md * md / ee));
      if (qb >= -kGrazing * ee * m_perp * std::sqrt(dd)) return std::numeric_limits<double>::infinity();
      t = 0;
    } else {
      const double disc = qb * qb - qa * qc;
      if (qb >= 0 || disc < 0) return std::numeric_limits<double>::infinity();
      t = (-qb - std::sqrt(disc)) / qa;
    }
    const double s = (md + t * de) / ee;
    if (s < 0 || s > 1) return std::numeric_limits<double>::infinity();
    // Grazing entry (the motion tangent to the cylinder where it enters, as when sliding on two coplanar triangles
    // across their shared edge): not a contact.
    const Eigen::Vector3d nrm = m + t * d - s * e;
    return t > 0 && -nrm.dot(d) < kGrazing * nrm.norm() * std::sqrt(dd) ? std::numeric_limits<double>::infinity() : t;
  };
  const Eigen::Vector3d lo = (a.cwiseMin(b).array() - radius).matrix(), hi = (a.cwiseMax(b).array() + radius).matrix();
  for_each_in_box(lo, hi, [&](int f) {
    const Tri& tri = tris_[static_cast<std::size_t>(f)];
    const Eigen::Vector3d& v0 = vertices_[tri.v[0]];
    const Eigen::Vector3d& n = face_normal_[static_cast<std::size_t>(f)];
    double t = std::numeric_limits<double>::infinity();
    // The face, offset by the radius towards the side `a` is on.
    const double s0 = n.dot(a - v0), sd = n.dot(d);
    const double side = s0 >= 0 ? 1.0 : -1.0;
    if (side * sd < -kGrazing * std::sqrt(dd)) {
      const double tf = std::max(0.0, (side * s0 - radius) / (-side * sd));
      if (tf <= 1) {
        const Eigen::Vector3d c = a + tf * d;
        const Eigen::Vector3d pc = c - n.dot(c - v0) * n;
        bool inside = true;
        for (int k = 0; k < 3 && inside; ++k) {
          const Eigen::Vector3d& p0 = vertices_[tri.v[k]];
          const Eigen::Vector3d& p1 = vertices_[tri.v[(k + 1) % 3]];
          inside = (p1 - p0).cross(pc - p0).dot(n) >= 0;
        }
        if (inside) t = tf;
      }
    }
    for (int k = 0; k < 3; ++k) {
      t = std::min(t, vertex_entry(vertices_[tri.v[k]]));
      t = std::min(t, edge_entry(vertices_[tri.v[k]], vertices_[tri.v[(k + 1) % 3]]));
    }
    if (t <= 1 && (t < best || (t == best && f < best_tri))) {
      best = t;
      best_tri = f;
    }
  });
  if (best_tri < 0) return out;
  out.hit = true;
  out.t = best;
  out.triangle = best_tri;
  out.centre = a + best * d;
  Eigen::Vector3d bary;
  const Eigen::Vector3d q = closest_on(out.centre, best_tri, bary);
  const Eigen::Vector3d off = out.centre - q;
  const double dist = off.norm();
  const Eigen::Vector3d& n = face_normal_[static_cast<std::size_t>(best_tri)];
  out.normal = dist > 0 ? Eigen::Vector3d(off / dist) : Eigen::Vector3d(n.dot(a - q) >= 0 ? n : Eigen::Vector3d(-n));
  return out;
}

}  // namespace surgsim::rigid
