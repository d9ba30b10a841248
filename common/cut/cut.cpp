// apply_cut: snap, split and separate (the method is described in cut.h), as stages on a working copy of the mesh:
// length scales, split_along_triangle for each blade triangle, remove_bad_pieces, open_faces, separate_nodes (with
// the manifold repair), then the result is assembled, compacted and validated before it replaces the input.
#include "cut/cut.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/hash.h"
#include "core/union_find.h"
#include "cut/components.h"

namespace surgsim::cut {

namespace {

using Vec3 = Eigen::Vector3d;
using Tet = std::array<int, 4>;
using Key = std::array<int, 3>;
using Edge = std::pair<int, int>;  // (low, high) node indices

// The four faces of a tet by local node positions (face f leaves out node f).
constexpr int kFaceNodes[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
constexpr int kEdgeNodes[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};

std::size_t at(int i) { return static_cast<std::size_t>(i); }

// One blade triangle: its vertices, unit normal, plane offset (n.x = c) and bounding box.
struct BladeTriangle {
  std::array<Vec3, 3> p;
  Vec3 n;
  double c = 0;
  Vec3 lo, hi;
  double size = 0;  // longest edge, m
};

// The mesh being cut: positions, length scales and tets, growing as edges are split.
struct Work {
  std::vector<Vec3> x;    // per working node, m
  std::vector<double> h;  // per working node: the length its snap tolerance is relative to, m
  std::vector<Tet> tets;
  std::vector<char> piece;  // per tet: a piece of a split tet
  std::vector<int> parent;  // per tet: the input tet it comes from
  std::vector<NodeOrigin> origins;
};

double volume(const std::vector<Vec3>& x, const Tet& t) {
  return (x[at(t[1])] - x[at(t[0])]).dot((x[at(t[2])] - x[at(t[0])]).cross(x[at(t[3])] - x[at(t[0])])) / 6.0;
}

double quality(const std::vector<Vec3>& x, const Tet& t) {
  double sum = 0;
  for (const auto& e : kEdgeNodes) sum += (x[at(t[at(e[0])])] - x[at(t[at(e[1])])]).squaredNorm();
  const double l_rms = std::sqrt(sum / 6);
  return l_rms > 0 ? 6 * std::sqrt(2.0) * std::abs(volume(x, t)) / (l_rms * l_rms * l_rms) : 0.0;
}

Key face_key(const Tet& t, int f) {
  Key k{t[at(kFaceNodes[f][0])], t[at(kFaceNodes[f][1])], t[at(kFaceNodes[f][2])]};
  std::sort(k.begin(), k.end());
  return k;
}

// Every face of the live tets, sorted by key (then tet), so that the two sides of an interior face are adjacent.
struct FaceRef {
  Key key;
  int tet;
  int local;
};
std::vector<FaceRef> sorted_faces(const std::vector<Tet>& tets, const std::vector<char>& removed) {
  std::vector<FaceRef> faces;
  faces.reserve(tets.size() * 4);
  for (std::size_t t = 0; t < tets.size(); ++t) {
    if (removed[t]) continue;
    for (int f = 0; f < 4; ++f) faces.push_back({face_key(tets[t], f), static_cast<int>(t), f});
  }
  std::sort(faces.begin(), faces.end(),
            [](const FaceRef& a, const FaceRef& b) { return a.key != b.key ? a.key < b.key : a.tet < b.tet; });
  return faces;
}

// Signed distances of the working nodes to a triangle's plane and their sides: 0 within snap h of it.
void classify(const Work& w, const BladeTriangle& b, double snap, std::vector<double>& dist,
              std::vector<signed char>& side) {
  dist.resize(w.x.size());
  side.resize(w.x.size());
  for (std::size_t i = 0; i < w.x.size(); ++i) {
    dist[i] = b.n.dot(w.x[i]) - b.c;
    side[i] = std::abs(dist[i]) <= snap * w.h[i] ? 0 : (dist[i] > 0 ? 1 : -1);
  }
}

// Separating axis test of a tet against a triangle: true when their interiors overlap by more than eps (m) along
// every axis (touching is not overlapping). Axes: the tet's face normals, the triangle's normal, and the cross
// products of their edges.
bool overlaps(const std::array<Vec3, 4>& tet, const BladeTriangle& b, double eps) {
  std::array<Vec3, 17 + 6> axes;
  std::size_t count = 0;
  for (const auto& f : kFaceNodes) {
    axes[count++] = (tet[at(f[1])] - tet[at(f[0])]).cross(tet[at(f[2])] - tet[at(f[0])]);
  }
  axes[count++] = b.n;
  for (const auto& e : kEdgeNodes) {
    const Vec3 te = tet[at(e[1])] - tet[at(e[0])];
    for (int k = 0; k < 3; ++k) axes[count++] = te.cross(b.p[at((k + 1) % 3)] - b.p[at(k)]);
  }
  for (std::size_t a = 0; a < count; ++a) {
    const double len = axes[a].norm();
    if (len <= 1e-12 * b.size * b.size) continue;  // parallel edges: no axis
    const Vec3 u = axes[a] / len;
    double tlo = std::numeric_limits<double>::infinity(), thi = -tlo, blo = tlo, bhi = -tlo;
    for (const Vec3& v : tet) {
      tlo = std::min(tlo, u.dot(v));
      thi = std::max(thi, u.dot(v));
    }
    for (const Vec3& v : b.p) {
      blo = std::min(blo, u.dot(v));
      bhi = std::max(bhi, u.dot(v));
    }
    if (thi <= blo + eps || bhi <= tlo + eps) return false;
  }
  return true;
}

// Whether the projection of point q on the triangle's plane lies inside the triangle (barycentric coordinates
// >= -1e-12).
bool projects_inside(const BladeTriangle& b, const Vec3& q) {
  const double area = (b.p[1] - b.p[0]).cross(b.p[2] - b.p[0]).dot(b.n);
  for (int k = 0; k < 3; ++k) {
    const Vec3& u = b.p[at((k + 1) % 3)];
    const Vec3& v = b.p[at((k + 2) % 3)];
    if ((u - q).cross(v - q).dot(b.n) / area < -1e-12) return false;
  }
  return true;
}

// Stage: split the tets the triangle crosses along its plane (cut.h, step 2), marking in input_split the input
// tets that lose their shape.
void split_along_triangle(Work& w, const BladeTriangle& b, double snap, std::vector<char>& input_split) {
  std::vector<double> dist;
  std::vector<signed char> side;
  classify(w, b, snap, dist, side);
  const double eps = 1e-9 * b.size;

  // The crossed tets' sign-changing edges.
  std::vector<Edge> edges;
  for (const Tet& t : w.tets) {
    bool plus = false, minus = false;
    Vec3 lo = w.x[at(t[0])], hi = lo;
    std::array<Vec3, 4> corners;
    for (int k = 0; k < 4; ++k) {
      corners[at(k)] = w.x[at(t[at(k)])];
      lo = lo.cwiseMin(corners[at(k)]);
      hi = hi.cwiseMax(corners[at(k)]);
      plus = plus || side[at(t[at(k)])] > 0;
      minus = minus || side[at(t[at(k)])] < 0;
    }
    if (!plus || !minus) continue;
    if ((lo.array() > b.hi.array()).any() || (hi.array() < b.lo.array()).any()) continue;
    if (!overlaps(corners, b, eps)) continue;
    for (const auto& e : kEdgeNodes) {
      const int p = t[at(e[0])], q = t[at(e[1])];
      if (side[at(p)] * side[at(q)] < 0) edges.emplace_back(std::min(p, q), std::max(p, q));
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  if (edges.empty()) return;
  const auto edge_index = [&edges](int p, int q) {
    const Edge e(std::min(p, q), std::max(p, q));
    const auto it = std::lower_bound(edges.begin(), edges.end(), e);
    return it != edges.end() && *it == e ? static_cast<int>(it - edges.begin()) : -1;
  };

  // The tets around each edge to split.
  std::vector<std::vector<int>> around(edges.size());
  for (std::size_t t = 0; t < w.tets.size(); ++t) {
    for (const auto& e : kEdgeNodes) {
      const int i = edge_index(w.tets[t][at(e[0])], w.tets[t][at(e[1])]);
      if (i >= 0) around[at(i)].push_back(static_cast<int>(t));
    }
  }

  // Bisect each edge in every tet around it, in edge order: tet (.., a, .., b, ..) becomes (.., a, .., p, ..) in
  // place and (.., p, .., b, ..) appended. The edges still to split that the tet holds follow their halves.
  for (std::size_t i = 0; i < edges.size(); ++i) {
    const auto [a, bn] = edges[i];
    const double t = dist[at(a)] / (dist[at(a)] - dist[at(bn)]);
    const int p = static_cast<int>(w.x.size());
    w.x.push_back((1 - t) * w.x[at(a)] + t * w.x[at(bn)]);
    w.h.push_back((1 - t) * w.h[at(a)] + t * w.h[at(bn)]);
    w.origins.push_back({NodeOrigin::Kind::kEdge, a, bn, t});
    for (const int ti : around[i]) {
      const Tet old = w.tets[at(ti)];
      Tet lower = old, upper = old;
      for (int k = 0; k < 4; ++k) {
        if (old[at(k)] == bn) lower[at(k)] = p;
        if (old[at(k)] == a) upper[at(k)] = p;
      }
      const int tu = static_cast<int>(w.tets.size());
      w.tets[at(ti)] = lower;
      w.tets.push_back(upper);
      w.piece[at(ti)] = 1;
      w.piece.push_back(1);
      const int input_tet = w.parent[at(ti)];
      w.parent.push_back(input_tet);
      input_split[at(input_tet)] = 1;
      for (const auto& e : kEdgeNodes) {
        const int u = old[at(e[0])], v = old[at(e[1])];
        const int j = edge_index(u, v);
        if (j <= static_cast<int>(i)) continue;
        const bool has_a = u == a || v == a, has_b = u == bn || v == bn;
        if (has_b) {
          std::replace(around[at(j)].begin(), around[at(j)].end(), ti, tu);
        } else if (!has_a) {
          around[at(j)].push_back(tu);
        }
      }
    }
  }
}

// Stage: the faces to open (cut.h, step 3): interior, on some triangle's plane between tets on its two sides,
// centroid inside it.
std::vector<Key> open_faces(const Work& w, const std::vector<BladeTriangle>& blade, double snap,
                            const std::vector<FaceRef>& faces) {
  std::vector<Key> open;
  std::vector<double> dist;
  std::vector<signed char> side;
  for (const BladeTriangle& b : blade) {
    classify(w, b, snap, dist, side);
    for (std::size_t i = 0; i + 1 < faces.size(); ++i) {
      if (faces[i].key != faces[i + 1].key) continue;
      const Key& k = faces[i].key;
      if (side[at(k[0])] != 0 || side[at(k[1])] != 0 || side[at(k[2])] != 0) continue;
      // The tets on the face's two sides lie on the plane's two sides (not a flat piece within snap of it).
      const int apex1 = w.tets[at(faces[i].tet)][at(faces[i].local)];
      const int apex2 = w.tets[at(faces[i + 1].tet)][at(faces[i + 1].local)];
      if (side[at(apex1)] * side[at(apex2)] >= 0) continue;
      if (projects_inside(b, (w.x[at(k[0])] + w.x[at(k[1])] + w.x[at(k[2])]) / 3.0)) open.push_back(k);
    }
  }
  std::sort(open.begin(), open.end());
  open.erase(std::unique(open.begin(), open.end()), open.end());
  return open;
}

// The boundary edges (as node pairs) on other than two boundary faces.
std::vector<Edge> non_manifold_edges(const std::vector<Tet>& tets, const std::vector<char>& removed) {
  const std::vector<FaceRef> faces = sorted_faces(tets, removed);
  std::vector<Edge> edges;
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i + 1;
    while (j < faces.size() && faces[j].key == faces[i].key) ++j;
    if (j - i == 1) {
      const Key& k = faces[i].key;
      edges.emplace_back(k[0], k[1]);
      edges.emplace_back(k[0], k[2]);
      edges.emplace_back(k[1], k[2]);
    }
    i = j;
  }
  std::sort(edges.begin(), edges.end());
  std::vector<Edge> bad;
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i + 1;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if (j - i != 2) bad.push_back(edges[i]);
    i = j;
  }
  return bad;
}

// Stage: separate the nodes of the open faces (cut.h, step 3). Returns the tets with copies in place, appends the
// copies to w (positions, origins) and closes again open faces on a non-manifold edge until none is left. `open`
// is updated to the faces actually opened.
std::vector<Tet> separate_nodes(Work& w, const std::vector<char>& removed, const std::vector<FaceRef>& faces,
                                std::vector<Key>& open) {
  const std::size_t nodes_before = w.x.size();
  for (;;) {
    // Corners (tet, local node) joined through the closed interior faces around their node.
    std::vector<int> parent(w.tets.size() * 4);
    for (std::size_t c = 0; c < parent.size(); ++c) parent[c] = static_cast<int>(c);
    std::vector<char> on_open(nodes_before, 0);
    for (const Key& k : open) {
      for (const int n : k) on_open[at(n)] = 1;
    }
    for (std::size_t i = 0; i + 1 < faces.size(); ++i) {
      if (faces[i].key != faces[i + 1].key || std::binary_search(open.begin(), open.end(), faces[i].key)) continue;
      const Tet& t1 = w.tets[at(faces[i].tet)];
      const Tet& t2 = w.tets[at(faces[i + 1].tet)];
      for (const int n : faces[i].key) {
        if (!on_open[at(n)]) continue;
        const int c1 = faces[i].tet * 4 + static_cast<int>(std::find(t1.begin(), t1.end(), n) - t1.begin());
        const int c2 = faces[i + 1].tet * 4 + static_cast<int>(std::find(t2.begin(), t2.end(), n) - t2.begin());
        const int r1 = core::find_root(parent, c1), r2 = core::find_root(parent, c2);
        if (r1 != r2) parent[at(std::max(r1, r2))] = std::min(r1, r2);
      }
    }
    // Each group of corners of a node past its first (in tet order) gets a copy of the node.
    std::vector<std::vector<std::pair<int, int>>> groups(nodes_before);  // per node: (root, node or copy)
    std::vector<Tet> tets = w.tets;
    std::vector<int> copy_of;  // per copy: the node copied
    for (std::size_t t = 0; t < tets.size(); ++t) {
      if (removed[t]) continue;
      for (int k = 0; k < 4; ++k) {
        const int n = w.tets[t][at(k)];
        if (!on_open[at(n)]) continue;
        const int root = core::find_root(parent, static_cast<int>(t) * 4 + k);
        auto& g = groups[at(n)];
        auto it = std::find_if(g.begin(), g.end(), [root](const auto& e) { return e.first == root; });
        if (it == g.end()) {
          const int id = g.empty() ? n : static_cast<int>(nodes_before + copy_of.size());
          if (!g.empty()) copy_of.push_back(n);
          g.emplace_back(root, id);
          it = g.end() - 1;
        }
        tets[t][at(k)] = it->second;
      }
    }
    // A boundary edge on other than two boundary faces closes the open faces on it; without any, done.
    const std::vector<Edge> bad = non_manifold_edges(tets, removed);
    std::vector<Key> keep;
    for (const Key& k : open) {
      bool on_bad = false;
      for (const Edge& e : bad) {
        const int a = e.first < static_cast<int>(nodes_before) ? e.first : copy_of[at(e.first) - nodes_before];
        const int b = e.second < static_cast<int>(nodes_before) ? e.second : copy_of[at(e.second) - nodes_before];
        const auto has = [&k](int n) { return std::find(k.begin(), k.end(), n) != k.end(); };
        on_bad = on_bad || (has(a) && has(b));
      }
      if (!on_bad) keep.push_back(k);
    }
    if (keep.size() == open.size()) {
      for (const int n : copy_of) {
        w.x.push_back(w.x[at(n)]);
        w.h.push_back(w.h[at(n)]);
        w.origins.push_back({NodeOrigin::Kind::kCopy, n, -1, 0});
      }
      return tets;
    }
    open = std::move(keep);
  }
}

CutResult refuse(const std::string& reason) {
  CutResult r;
  r.status = CutStatus::kRefused;
  r.reason = reason;
  return r;
}

// The cut with checked inputs (cut.h, steps 1-4): replaces `mesh` only when the result is valid.
CutResult cut_checked(mesh::TetMesh& mesh, const std::vector<BladeTriangle>& tris, const CutOptions& options,
                      const std::vector<char>& is_protected) {
  const auto nv = static_cast<int>(mesh.nodes.rows());
  const auto nt = static_cast<int>(mesh.tets.rows());

  // Working copy; each node's length scale is the mean length of its tets' edges.
  Work w;
  w.x.resize(at(nv));
  for (int i = 0; i < nv; ++i) w.x[at(i)] = mesh.nodes.row(i).transpose();
  w.h.assign(at(nv), 0.0);
  std::vector<int> uses(at(nv), 0);
  w.tets.resize(at(nt));
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 4; ++k) w.tets[at(t)][at(k)] = mesh.tets(t, k);
    for (const auto& e : kEdgeNodes) {
      const int a = mesh.tets(t, e[0]), b = mesh.tets(t, e[1]);
      const double len = (w.x[at(a)] - w.x[at(b)]).norm();
      w.h[at(a)] += len;
      w.h[at(b)] += len;
      ++uses[at(a)];
      ++uses[at(b)];
    }
  }
  for (int i = 0; i < nv; ++i) w.h[at(i)] = uses[at(i)] > 0 ? w.h[at(i)] / uses[at(i)] : 0.0;
  w.piece.assign(at(nt), 0);
  w.parent.resize(at(nt));
  for (int t = 0; t < nt; ++t) w.parent[at(t)] = t;

  CutResult r;
  for (int t = 0; t < nt; ++t) r.volume_before += volume(w.x, w.tets[at(t)]);

  // Split along each triangle's plane.
  std::vector<char> input_split(at(nt), 0);
  for (const BladeTriangle& b : tris) split_along_triangle(w, b, options.snap, input_split);

  // Pieces the validator would refuse or of low quality.
  std::vector<char> removed(w.tets.size(), 0);
  double mean = 0;
  for (const Tet& t : w.tets) mean += std::abs(volume(w.x, t));
  mean /= static_cast<double>(w.tets.size());
  for (std::size_t t = 0; t < w.tets.size(); ++t) {
    if (!w.piece[t]) continue;
    const double v = volume(w.x, w.tets[t]);
    if (v <= 1e-10 * mean || quality(w.x, w.tets[t]) < options.min_quality) {
      removed[t] = 1;
      ++r.elements_removed;
      r.volume_removed += v;
    }
  }

  // Open the faces on the blade, refusing a cut through a protected node, and separate their nodes.
  const std::vector<FaceRef> faces = sorted_faces(w.tets, removed);
  std::vector<Key> open = open_faces(w, tris, options.snap, faces);
  for (const Key& k : open) {
    for (const int n : k) {
      if (n < nv && is_protected[at(n)]) {
        return refuse("the blade crosses protected node " + std::to_string(n) + ": the cut is refused");
      }
    }
  }
  const std::size_t working_nodes = w.x.size();
  const std::vector<Tet> tets = separate_nodes(w, removed, faces, open);

  // Assemble, drop the removed pieces and the nodes left without a tet, validate.
  mesh::TetMesh cut;
  cut.source = mesh.source;
  cut.nodes.resize(static_cast<Eigen::Index>(w.x.size()), 3);
  for (std::size_t i = 0; i < w.x.size(); ++i) cut.nodes.row(static_cast<Eigen::Index>(i)) = w.x[i].transpose();
  cut.tets.resize(static_cast<Eigen::Index>(tets.size()), 4);
  for (std::size_t t = 0; t < tets.size(); ++t) {
    for (int k = 0; k < 4; ++k) cut.tets(static_cast<Eigen::Index>(t), k) = tets[t][at(k)];
  }
  if (!mesh.ids.empty()) {
    cut.ids = mesh.ids;
    std::int64_t next = *std::max_element(mesh.ids.begin(), mesh.ids.end());
    while (cut.ids.size() < w.x.size()) cut.ids.push_back(++next);
  }
  if (!mesh.tet_ids.empty()) {
    cut.tet_ids = mesh.tet_ids;
    std::int64_t next = *std::max_element(mesh.tet_ids.begin(), mesh.tet_ids.end());
    while (cut.tet_ids.size() < tets.size()) cut.tet_ids.push_back(++next);
  }
  std::vector<int> removed_list;
  for (std::size_t t = 0; t < removed.size(); ++t) {
    if (removed[t]) removed_list.push_back(static_cast<int>(t));
  }
  Compacted compact = remove_elements(cut, removed_list);
  try {
    mesh::MeshValidation strict;
    strict.fix_orientation = false;
    mesh::validate_mesh(compact.mesh, strict);
  } catch (const core::Error& e) {
    CutResult f = refuse(std::string("the cut mesh would be invalid: ") + e.what());
    f.elements_removed = r.elements_removed;
    return f;
  }

  // Commit.
  for (int t = 0; t < nt; ++t) r.elements_split += input_split[at(t)];
  for (std::size_t t = 0; t < w.piece.size(); ++t) r.elements_created += w.piece[t] && !removed[t] ? 1 : 0;
  r.nodes_created = static_cast<int>(working_nodes) - nv;
  r.nodes_duplicated = static_cast<int>(w.x.size() - working_nodes);
  r.faces_opened = static_cast<int>(open.size());
  for (int t = 0; t < compact.mesh.tets.rows(); ++t) r.volume_after += mesh::tet_volume(compact.mesh, t);
  r.origins = std::move(w.origins);
  r.node_map = std::move(compact.node_map);
  r.topology_hash = cut_topology_hash(compact.mesh);
  r.status = CutStatus::kApplied;
  mesh = std::move(compact.mesh);
  return r;
}

}  // namespace

Blade blade_quad(const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec3& p3) {
  Blade b;
  Eigen::Matrix3d t;
  t << p0.transpose(), p1.transpose(), p2.transpose();
  b.triangles.push_back(t);
  t << p0.transpose(), p2.transpose(), p3.transpose();
  b.triangles.push_back(t);
  return b;
}

std::uint64_t cut_topology_hash(const mesh::TetMesh& mesh) {
  core::Hasher h;
  h.value<std::uint64_t>(static_cast<std::uint64_t>(mesh.nodes.rows()));
  h.value<std::uint64_t>(static_cast<std::uint64_t>(mesh.tets.rows()));
  for (Eigen::Index t = 0; t < mesh.tets.rows(); ++t) {
    for (int k = 0; k < 4; ++k) h.value<std::int32_t>(mesh.tets(t, k));
  }
  return h.digest();
}

CutResult apply_cut(mesh::TetMesh& mesh, const Blade& blade, const CutOptions& options) {
  const auto nv = static_cast<int>(mesh.nodes.rows());
  const auto nt = static_cast<int>(mesh.tets.rows());

  // Inputs.
  if (!(options.snap >= 0 && options.snap < 0.5)) return refuse("options.snap must lie in [0, 0.5)");
  if (!(options.min_quality >= 0 && options.min_quality < 1)) return refuse("options.min_quality must lie in [0, 1)");
  if (nt == 0) return refuse("the mesh has no tetrahedra");
  if ((mesh.tets.array() < 0).any() || (mesh.tets.array() >= nv).any()) {
    return refuse("the mesh has a node index out of range: validate it first");
  }
  std::vector<char> is_protected(at(nv), 0);
  for (const int n : options.protected_nodes) {
    if (n < 0 || n >= nv) return refuse("protected node " + std::to_string(n) + " is not in the mesh");
    is_protected[at(n)] = 1;
  }
  std::vector<BladeTriangle> tris;
  for (std::size_t i = 0; i < blade.triangles.size(); ++i) {
    const Eigen::Matrix3d& m = blade.triangles[i];
    if (!m.allFinite()) return refuse("blade triangle " + std::to_string(i) + " has a non-finite vertex");
    BladeTriangle b;
    for (int k = 0; k < 3; ++k) b.p[at(k)] = m.row(k).transpose();
    const Vec3 n = (b.p[1] - b.p[0]).cross(b.p[2] - b.p[0]);
    b.size = std::max({(b.p[1] - b.p[0]).norm(), (b.p[2] - b.p[1]).norm(), (b.p[0] - b.p[2]).norm()});
    if (!(n.norm() > 1e-12 * b.size * b.size)) {
      return refuse("blade triangle " + std::to_string(i) + " is degenerate (no area)");
    }
    b.n = n.normalized();
    b.c = b.n.dot(b.p[0]);
    b.lo = b.p[0].cwiseMin(b.p[1]).cwiseMin(b.p[2]);
    b.hi = b.p[0].cwiseMax(b.p[1]).cwiseMax(b.p[2]);
    tris.push_back(b);
  }

  // Where removing low-quality pieces leaves an invalid mesh (e.g. two holes sharing an edge), the cut keeps them.
  CutResult r = cut_checked(mesh, tris, options, is_protected);
  if (r.status == CutStatus::kRefused && r.elements_removed > 0 && options.min_quality > 0) {
    CutOptions keep = options;
    keep.min_quality = 0;
    r = cut_checked(mesh, tris, keep, is_protected);
  }
  return r;
}

Eigen::MatrixXd carry_node_field(const CutResult& result, const Eigen::MatrixXd& input_field) {
  const std::size_t working = result.node_map.size();
  if (result.status != CutStatus::kApplied || working < result.origins.size() ||
      static_cast<std::size_t>(input_field.rows()) != working - result.origins.size()) {
    core::throw_error("carry_node_field: the field has ", input_field.rows(), " rows, the cut's input ",
                      working - std::min(working, result.origins.size()), " nodes (or the cut was refused)");
  }
  Eigen::MatrixXd field(static_cast<Eigen::Index>(working), input_field.cols());
  field.topRows(input_field.rows()) = input_field;
  for (std::size_t i = 0; i < result.origins.size(); ++i) {
    const NodeOrigin& o = result.origins[i];
    const auto row = static_cast<Eigen::Index>(working - result.origins.size() + i);
    field.row(row) = o.kind == NodeOrigin::Kind::kEdge ? ((1 - o.t) * field.row(o.a) + o.t * field.row(o.b)).eval()
                                                       : field.row(o.a).eval();
  }
  const int rows = result.node_map.empty() ? 0 : *std::max_element(result.node_map.begin(), result.node_map.end()) + 1;
  Eigen::MatrixXd out(rows, input_field.cols());
  for (std::size_t i = 0; i < working; ++i) {
    if (result.node_map[i] >= 0) out.row(result.node_map[i]) = field.row(static_cast<Eigen::Index>(i));
  }
  return out;
}

}  // namespace surgsim::cut
