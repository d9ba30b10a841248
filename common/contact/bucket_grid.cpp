#include "contact/bucket_grid.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"
#include "mesh/geometry.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::contact {

namespace {
constexpr std::uint64_t kEmpty = ~0ull;
constexpr int kBits = 21;  // per cell coordinate in a key
}  // namespace

Eigen::Vector3d barycentric_weights(const Eigen::Vector3d& bary) { return bary / bary.squaredNorm(); }

BucketGrid::BucketGrid(const TetMesh& mesh, const SurfaceMesh& surface, double cell_size, double margin)
    : rest_(&mesh.nodes), surface_(&surface) {
  if (surface.nodes.empty() || surface.tris.rows() == 0) throw_error(mesh.source, ": the mesh has no boundary surface");
  // Cell size: about twice the mean surface edge, so a cell and its neighbours hold a few dozen nodes.
  if (cell_size <= 0) {
    double sum = 0;
    for (int f = 0; f < surface.tris.rows(); ++f) {
      for (int e = 0; e < 3; ++e) {
        sum += (mesh.nodes.row(surface.tris(f, e)) - mesh.nodes.row(surface.tris(f, (e + 1) % 3))).norm();
      }
    }
    cell_size = 2.0 * sum / (3.0 * static_cast<double>(surface.tris.rows()));
  }
  cell_ = cell_size;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::max());
  Eigen::Vector3d hi = -lo;
  for (int n : surface.nodes) {
    lo = lo.cwiseMin(mesh.nodes.row(n).transpose());
    hi = hi.cwiseMax(mesh.nodes.row(n).transpose());
  }
  origin_ = lo - Eigen::Vector3d::Constant(margin);
  for (int c = 0; c < 3; ++c) {
    dims_[c] = static_cast<int>(std::ceil((hi[c] - lo[c] + 2 * margin) / cell_)) + 1;
    if (dims_[c] >= (1 << kBits)) throw_error(mesh.source, ": bucket grid too fine (", dims_[c], " cells on an axis)");
  }

  // Bucket the surface nodes: sort (key, node) pairs, then fill the open-addressing table with CSR ranges.
  std::vector<std::pair<std::uint64_t, int>> pairs;
  pairs.reserve(surface.nodes.size());
  for (int n : surface.nodes) {
    int i, j, k;
    cell_of(mesh.nodes.row(n).transpose(), i, j, k);
    pairs.emplace_back(key(i, j, k), n);
  }
  std::sort(pairs.begin(), pairs.end());
  std::size_t cells = 0;
  for (std::size_t a = 0; a < pairs.size(); ++a) cells += (a == 0 || pairs[a].first != pairs[a - 1].first);
  std::size_t size = 16;
  while (size < 2 * cells) size <<= 1;
  keys_.assign(size, kEmpty);
  start_.assign(size, 0);
  count_.assign(size, 0);
  cell_nodes_.resize(pairs.size());
  for (std::size_t a = 0; a < pairs.size(); ++a) {
    cell_nodes_[a] = pairs[a].second;
    if (a > 0 && pairs[a].first == pairs[a - 1].first) continue;
    std::size_t slot = (pairs[a].first * 0x9E3779B97F4A7C15ull) & (size - 1);
    while (keys_[slot] != kEmpty) slot = (slot + 1) & (size - 1);
    keys_[slot] = pairs[a].first;
    start_[slot] = static_cast<int>(a);
    std::size_t b = a;
    while (b < pairs.size() && pairs[b].first == pairs[a].first) ++b;
    count_[slot] = static_cast<int>(b - a);
  }

  // Node -> incident triangles.
  const int nv = static_cast<int>(mesh.nodes.rows());
  node_tris_ = node_triangles(surface, nv);
  node_mark_.assign(nv, 0);
  tri_mark_.assign(surface.tris.rows(), 0);
}

std::uint64_t BucketGrid::key(int i, int j, int k) const {
  return (static_cast<std::uint64_t>(i) << (2 * kBits)) | (static_cast<std::uint64_t>(j) << kBits) |
         static_cast<std::uint64_t>(k);
}

int BucketGrid::find_slot(std::uint64_t k) const {
  const std::size_t mask = keys_.size() - 1;
  std::size_t slot = (k * 0x9E3779B97F4A7C15ull) & mask;
  while (keys_[slot] != kEmpty) {
    if (keys_[slot] == k) return static_cast<int>(slot);
    slot = (slot + 1) & mask;
  }
  return -1;
}

void BucketGrid::cell_of(const Eigen::Vector3d& p, int& i, int& j, int& k) const {
  const Eigen::Vector3d r = (p - origin_) / cell_;
  i = static_cast<int>(std::floor(r.x()));
  j = static_cast<int>(std::floor(r.y()));
  k = static_cast<int>(std::floor(r.z()));
}

int BucketGrid::candidates_near(const Eigen::Vector3d& p, int* out, int capacity) const {
  return gather_cells(p, p, out, capacity);
}

// Surface nodes in the cells along [p0, p1] and their 26 neighbours, each once.
int BucketGrid::gather_cells(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, int* nodes, int capacity) const {
  if (!p0.allFinite() || !p1.allFinite()) return 0;
  if (++stamp_ == 0) {
    std::fill(node_mark_.begin(), node_mark_.end(), 0);
    std::fill(tri_mark_.begin(), tri_mark_.end(), 0);
    stamp_ = 1;
  }
  const double len = (p1 - p0).norm();
  const int steps = std::min(1 + static_cast<int>(std::ceil(len / (0.5 * cell_))), 4096);
  int count = 0;
  int last_i = INT32_MIN, last_j = INT32_MIN, last_k = INT32_MIN;
  for (int st = 0; st <= steps; ++st) {
    const Eigen::Vector3d p = p0 + (p1 - p0) * (static_cast<double>(st) / steps);
    int ci, cj, ck;
    cell_of(p, ci, cj, ck);
    if (ci == last_i && cj == last_j && ck == last_k) continue;
    last_i = ci, last_j = cj, last_k = ck;
    for (int di = -1; di <= 1; ++di) {
      for (int dj = -1; dj <= 1; ++dj) {
        for (int dk = -1; dk <= 1; ++dk) {
          const int i = ci + di, j = cj + dj, k = ck + dk;
          if (i < 0 || j < 0 || k < 0 || i >= dims_[0] || j >= dims_[1] || k >= dims_[2]) continue;
          const int slot = find_slot(key(i, j, k));
          if (slot < 0) continue;
          for (int a = start_[slot]; a < start_[slot] + count_[slot]; ++a) {
            const int n = cell_nodes_[a];
            if (node_mark_[n] == stamp_) continue;
            node_mark_[n] = stamp_;
            if (count == capacity) return count;
            nodes[count++] = n;
          }
        }
      }
    }
  }
  return count;
}

int BucketGrid::triangles_of(const int* nodes, int count, int* tris, int capacity) const {
  int n_tris = 0;
  for (int a = 0; a < count; ++a) {
    for (int t = node_tris_.start[nodes[a]]; t < node_tris_.start[nodes[a] + 1]; ++t) {
      const int f = node_tris_.list[t];
      if (tri_mark_[f] == stamp_) continue;
      tri_mark_[f] = stamp_;
      if (n_tris == capacity) return n_tris;
      tris[n_tris++] = f;
    }
  }
  return n_tris;
}

// Tests surface triangle f against [p0, p1] and keeps the earliest crossing from outside in `best`.
void BucketGrid::test_triangle(int f, const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, PositionFn positions,
                               const void* context, SurfaceHit& best) const {
  Eigen::Vector3d v[3];
  for (int e = 0; e < 3; ++e) {
    const int n = surface_->tris(f, e);
    if (positions != nullptr) {
      positions(context, n, v[e]);
    } else {
      v[e] = rest_->row(n).transpose();
    }
  }
  // Only crossings from outside to inside count (the outward normal faces the segment's start).
  const Eigen::Vector3d normal = (v[1] - v[0]).cross(v[2] - v[0]);
  if (normal.dot(p1 - p0) >= 0) return;
  double s;
  Eigen::Vector3d bary;
  if (segment_triangle(p0, p1, v[0], v[1], v[2], s, bary) && s < best.s) {
    best.hit = true;
    best.s = s;
    best.triangle = f;
    best.nodes = {surface_->tris(f, 0), surface_->tris(f, 1), surface_->tris(f, 2)};
    best.bary = bary;
    best.point = p0 + s * (p1 - p0);
  }
}

SurfaceHit BucketGrid::segment_query(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, PositionFn positions,
                                     const void* context) const {
  SurfaceHit best;
  best.s = 2.0;
  int nodes[kMaxCandidates];
  int tris[kMaxTriangles];
  const int n_nodes = gather_cells(p0, p1, nodes, kMaxCandidates);
  const int n_tris = triangles_of(nodes, n_nodes, tris, kMaxTriangles);
  for (int a = 0; a < n_tris; ++a) test_triangle(tris[a], p0, p1, positions, context, best);
  if (!best.hit) best.s = 0;
  return best;
}

SurfaceHit BucketGrid::segment_query_brute(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, PositionFn positions,
                                           const void* context) const {
  SurfaceHit best;
  best.s = 2.0;
  for (int f = 0; f < surface_->tris.rows(); ++f) test_triangle(f, p0, p1, positions, context, best);
  if (!best.hit) best.s = 0;
  return best;
}

SurfaceProjection BucketGrid::project_rest(const Eigen::Vector3d& p, int radius, const Eigen::Vector3d* facing) const {
  SurfaceProjection best;
  int nodes[kMaxCandidates];
  int tris[kMaxTriangles];
  int n_nodes = gather_cells(p, p, nodes, kMaxCandidates);
  // Widen once when the point is further from the surface than a cell.
  if (n_nodes == 0 && radius > 1) {
    const Eigen::Vector3d off = Eigen::Vector3d::Constant(cell_ * (radius - 1));
    n_nodes = gather_cells(p - off, p + off, nodes, kMaxCandidates);
  }
  const int n_tris = triangles_of(nodes, n_nodes, tris, kMaxTriangles);
  double best_d2 = std::numeric_limits<double>::max();
  for (int a = 0; a < n_tris; ++a) {
    const int f = tris[a];
    const Eigen::Vector3d A = rest_->row(surface_->tris(f, 0)).transpose();
    const Eigen::Vector3d B = rest_->row(surface_->tris(f, 1)).transpose();
    const Eigen::Vector3d C = rest_->row(surface_->tris(f, 2)).transpose();
    if (facing != nullptr) {
      const Eigen::Vector3d n = (B - A).cross(C - A);
      if (n.dot(*facing) <= kFacingCos * n.norm() * facing->norm()) continue;  // faces away: the other side
    }
    Eigen::Vector3d bary;
    const Eigen::Vector3d q = closest_point_triangle(p, A, B, C, bary);
    const double d2 = (q - p).squaredNorm();
    if (d2 < best_d2) {
      best_d2 = d2;
      best.found = true;
      best.triangle = f;
      best.nodes = {surface_->tris(f, 0), surface_->tris(f, 1), surface_->tris(f, 2)};
      best.bary = bary;
      best.point = q;
      best.normal = (B - A).cross(C - A).normalized();
    }
  }
  if (best.found) best.distance = std::sqrt(best_d2);
  return best;
}

int BucketGrid::nearest_node(const Eigen::Vector3d& p) const {
  int nodes[kMaxCandidates];
  const int n = gather_cells(p, p, nodes, kMaxCandidates);
  int best = -1;
  double best_d2 = std::numeric_limits<double>::max();
  for (int a = 0; a < n; ++a) {
    const double d2 = (rest_->row(nodes[a]).transpose() - p).squaredNorm();
    if (d2 < best_d2) best_d2 = d2, best = nodes[a];
  }
  return best;
}

}  // namespace surgsim::contact
