#include "fem/fixed_set.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <sstream>

#include "core/error.h"
#include "core/union_find.h"
#include "core/hash.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::fem {

FixedSet::FixedSet(int node_count, const std::vector<int>& fixed_nodes) {
  if (node_count < 0) throw_error("fixed set: negative node count ", node_count);
  masks_.assign(static_cast<std::size_t>(node_count), 0);
  for (int n : fixed_nodes) {
    if (n < 0 || n >= node_count)
      throw_error("fixed node ", n, " is out of range: the mesh has ", node_count, " nodes (0..", node_count - 1, ")");
    masks_[static_cast<std::size_t>(n)] = 7;
  }
  number();
}

FixedSet::FixedSet(std::vector<std::uint8_t> component_masks) : masks_(std::move(component_masks)) {
  for (auto& m : masks_) m &= 7;
  number();
}

void FixedSet::number() {
  free_index_.assign(masks_.size() * 3, -1);
  free_dofs_.clear();
  for (std::size_t dof = 0; dof < free_index_.size(); ++dof)
    if (!(masks_[dof / 3] & (1u << (dof % 3)))) {
      free_index_[dof] = static_cast<int>(free_dofs_.size());
      free_dofs_.push_back(static_cast<int>(dof));
    }
}

std::vector<int> FixedSet::fixed_nodes() const {
  std::vector<int> out;
  for (int n = 0; n < node_count(); ++n)
    if (node_touched(n)) out.push_back(n);
  return out;
}

std::uint64_t FixedSet::hash() const {
  Hasher h;
  h.str("FixedSet/1");
  h.value<std::uint64_t>(masks_.size());
  if (!masks_.empty()) h.bytes(masks_.data(), masks_.size());
  return h.digest();
}

std::vector<int> nodes_in_region(const TetMesh& mesh, const FixedRegion& region) {
  const int n = static_cast<int>(mesh.nodes.rows());
  std::vector<char> hit(static_cast<std::size_t>(n), 0);
  for (int i : region.nodes) {
    if (i < 0 || i >= n)
      throw_error("fixed node ", i, " is out of range: the mesh", (mesh.source.empty() ? "" : " " + mesh.source),
                  " has ", n, " nodes (0..", n - 1, ")");
    hit[static_cast<std::size_t>(i)] = 1;
  }
  if (n > 0) {
    const double tol = 1e-9 * (mesh.nodes.colwise().maxCoeff() - mesh.nodes.colwise().minCoeff()).norm();
    const auto& boxes = region.boxes;
    const Eigen::Vector3d normal = region.plane_normal.normalized();
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d x = region.frame.to_organ(mesh.nodes.row(i).transpose());
      for (const auto& b : boxes)
        if ((x.array() >= b.first.array() - tol).all() && (x.array() <= b.second.array() + tol).all())
          hit[static_cast<std::size_t>(i)] = 1;
      if (region.has_plane && (x - region.plane_point).dot(normal) >= -tol) hit[static_cast<std::size_t>(i)] = 1;
    }
  }
  std::vector<int> out;
  for (int i = 0; i < n; ++i)
    if (hit[static_cast<std::size_t>(i)]) out.push_back(i);
  return out;
}

FixedSet fixed_set_from_region(const TetMesh& mesh, const FixedRegion& region) {
  return FixedSet(static_cast<int>(mesh.nodes.rows()), nodes_in_region(mesh, region));
}

namespace {

std::string list_nodes(const std::vector<int>& nodes, std::size_t max_shown = 12) {
  std::ostringstream os;
  for (std::size_t i = 0; i < nodes.size() && i < max_shown; ++i) os << (i ? ", " : "") << nodes[i];
  if (nodes.size() > max_shown) os << ", ... (" << nodes.size() - max_shown << " more)";
  return os.str();
}

// Unit vector with tiny components zeroed and its largest component positive (stable text in messages).
Eigen::Vector3d canonical_direction(Eigen::Vector3d v) {
  v.normalize();
  Eigen::Index big = 0;
  v.cwiseAbs().maxCoeff(&big);
  if (v[big] < 0) v = -v;
  for (int a = 0; a < 3; ++a)
    if (std::abs(v[a]) < 1e-9) v[a] = 0;
  return v;
}

}  // namespace

namespace {

// Mechanically independent parts: tetrahedra sharing a face (3 nodes) move as one body; a shared vertex or edge is
// a hinge. Union-find over tets through their sorted faces, O(T log T).
struct MeshParts {
  std::vector<int> tet_part;                 // #T, part index 0..count-1 (numbered by first tet)
  std::vector<std::vector<int>> nodes;       // per part, its nodes ascending
  std::vector<std::vector<int>> node_parts;  // per node, the parts using it ascending (empty: in no tet)
  int count() const { return static_cast<int>(nodes.size()); }
};

MeshParts face_connected_parts(const TetMesh& mesh) {
  const int n = static_cast<int>(mesh.nodes.rows());
  const int t_count = static_cast<int>(mesh.tets.rows());
  // Each face as one sortable key: its sorted node indices packed in 21 bits each (meshes up to 2^21 nodes), else
  // the node triple itself.
  const bool packed = n < (1 << 21);
  struct Face {
    std::uint64_t key;
    std::array<int, 3> v;
    int tet;
  };
  std::vector<Face> faces;
  faces.reserve(static_cast<std::size_t>(t_count) * 4);
  for (int t = 0; t < t_count; ++t)
    for (int skip = 0; skip < 4; ++skip) {
      Face f{0, {0, 0, 0}, t};
      int k = 0;
      for (int a = 0; a < 4; ++a)
        if (a != skip) f.v[static_cast<std::size_t>(k++)] = mesh.tets(t, a);
      std::sort(f.v.begin(), f.v.end());
      if (packed)
        f.key = (static_cast<std::uint64_t>(f.v[0]) << 42) | (static_cast<std::uint64_t>(f.v[1]) << 21) |
                static_cast<std::uint64_t>(f.v[2]);
      faces.push_back(f);
    }
  if (packed)
    std::sort(faces.begin(), faces.end(), [](const Face& a, const Face& b) { return a.key < b.key; });
  else
    std::sort(faces.begin(), faces.end(), [](const Face& a, const Face& b) { return a.v < b.v; });
  std::vector<int> parent(static_cast<std::size_t>(t_count));
  std::iota(parent.begin(), parent.end(), 0);
  for (std::size_t i = 1; i < faces.size(); ++i)
    if (faces[i].v == faces[i - 1].v) {
      const int r0 = find_root(parent, faces[i - 1].tet), r1 = find_root(parent, faces[i].tet);
      if (r0 != r1) parent[static_cast<std::size_t>(std::max(r0, r1))] = std::min(r0, r1);
    }
  MeshParts parts;
  parts.tet_part.assign(static_cast<std::size_t>(t_count), -1);
  parts.node_parts.assign(static_cast<std::size_t>(n), {});
  std::vector<int> root_part(static_cast<std::size_t>(t_count), -1);
  for (int t = 0; t < t_count; ++t) {
    int& p = root_part[static_cast<std::size_t>(find_root(parent, t))];
    if (p < 0) p = static_cast<int>(parts.nodes.size()), parts.nodes.emplace_back();
    parts.tet_part[static_cast<std::size_t>(t)] = p;
    for (int a = 0; a < 4; ++a) {
      const int v = mesh.tets(t, a);
      if (v < 0 || v >= n) continue;                               // validate_mesh reports it
      auto& list = parts.node_parts[static_cast<std::size_t>(v)];  // a node is in few parts: a linear scan
      if (std::find(list.begin(), list.end(), p) == list.end()) list.push_back(p);
    }
  }
  for (int v = 0; v < n; ++v) {
    auto& list = parts.node_parts[static_cast<std::size_t>(v)];
    std::sort(list.begin(), list.end());
    for (int p : list) parts.nodes[static_cast<std::size_t>(p)].push_back(v);  // ascending
  }
  return parts;
}

// How part p is attached to the others (it shares no face with them by construction): "is not attached to
// anything ..." or "touches part 1 only at node 17 (a vertex hinge)" / "... along the edge 17-18 (an edge hinge)".
std::string describe_attachment(const TetMesh& mesh, const MeshParts& parts, int p) {
  std::vector<std::pair<int, int>> shared;  // (other part, node)
  for (int v : parts.nodes[static_cast<std::size_t>(p)])
    for (int q : parts.node_parts[static_cast<std::size_t>(v)])
      if (q != p) shared.emplace_back(q, v);
  if (shared.empty())
    return "is not attached to anything (it shares no node with the other parts: the mesh is not connected)";
  std::sort(shared.begin(), shared.end());
  std::ostringstream os;
  os << "is joined to the rest only through hinges (a shared vertex or edge, about which it can turn; only shared "
        "faces attach): it";
  std::size_t i = 0;
  int shown = 0;
  while (i < shared.size()) {
    std::size_t j = i;
    std::vector<int> nodes;
    while (j < shared.size() && shared[j].first == shared[i].first) nodes.push_back(shared[j++].second);
    const int q = shared[i].first;
    if (shown == 3) {
      os << "; and touches other parts too";
      break;
    }
    os << (shown ? "; and" : "") << " touches part " << q + 1;
    if (nodes.size() == 1) {
      os << " only at node " << nodes[0] << " (a vertex hinge)";
    } else {
      bool edge = false;
      if (nodes.size() == 2)
        for (Eigen::Index t = 0; t < mesh.tets.rows() && !edge; ++t) {
          if (parts.tet_part[static_cast<std::size_t>(t)] != p) continue;
          int hits = 0;
          for (int a = 0; a < 4; ++a) hits += (mesh.tets(t, a) == nodes[0] || mesh.tets(t, a) == nodes[1]);
          edge = hits == 2;
        }
      if (edge)
        os << " along the edge " << nodes[0] << "-" << nodes[1] << " (an edge hinge)";
      else
        os << " at nodes " << list_nodes(nodes, 6) << " (vertices and edges only, no shared face)";
    }
    ++shown;
    i = j;
  }
  return os.str();
}

}  // namespace

void check_rigid_modes_removed(const TetMesh& mesh, const FixedSet& fixed, const std::string& where) {
  const int n = static_cast<int>(mesh.nodes.rows());
  const std::string prefix = where.empty() ? std::string() : where + ": ";
  const std::string fix_hint =
      "fix at least 3 non-collinear nodes (scene key 'fixed': nodes, box, boxes or plane; programs: --fixed i,j,k, "
      "--fixed-box or --fixed-plane)";
  if (fixed.node_count() != n)
    throw_error(prefix, "fixed set is for ", fixed.node_count(), " nodes but the mesh has ", n);
  const std::vector<int> fixed_nodes = fixed.fixed_nodes();
  if (fixed_nodes.empty())
    throw_error(prefix, "no node is fixed, so the organ can translate and rotate freely (6 rigid modes): ", fix_hint);

  // Mechanically independent parts (tets sharing a face). A part is held only by its own fixed dofs: a node it
  // shares with another part is a hinge, which leaves the rotations about it free.
  MeshParts parts = face_connected_parts(mesh);
  if (mesh.tets.rows() == 0) {  // no element at all: validate_mesh reports it; treat the nodes as one body
    parts.nodes.assign(1, std::vector<int>(static_cast<std::size_t>(n)));
    std::iota(parts.nodes[0].begin(), parts.nodes[0].end(), 0);
  }

  // Per part: the rigid modes (3 translations, 3 rotations about the part's centroid, scaled by its size) evaluated
  // at the fixed dofs. A mode is free when this 6-column matrix has a null vector.
  for (int p = 0; p < parts.count(); ++p) {
    const std::vector<int>& nodes = parts.nodes[static_cast<std::size_t>(p)];
    std::vector<int> part_fixed;
    for (int i : nodes)
      if (i >= 0 && i < n && fixed.node_touched(i)) part_fixed.push_back(i);
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int i : nodes) centroid += mesh.nodes.row(i).transpose();
    centroid /= static_cast<double>(nodes.size());
    double size = 0;
    for (int i : nodes) size = std::max(size, (mesh.nodes.row(i).transpose() - centroid).norm());
    if (size <= 0) size = 1;
    const bool one_part = parts.count() == 1;
    const std::string part = one_part ? std::string("the organ")
                                      : "part " + std::to_string(p + 1) + " of " + std::to_string(parts.count()) +
                                            " of the mesh (" + std::to_string(nodes.size()) + " of " +
                                            std::to_string(n) + " nodes: " + list_nodes(nodes, 6) + ")";
    // "; " + the fix for one body; ". Part 2 touches ...: " + the fix for a part among several.
    const std::string fix =
        one_part
            ? "; " + fix_hint
            : ". Part " + std::to_string(p + 1) + " " + describe_attachment(mesh, parts, p) +
                  ". Either fix at least 3 non-collinear nodes of that part (scene key 'fixed': nodes, box, boxes or "
                  "plane; programs: --fixed i,j,k, --fixed-box or --fixed-plane), merge the bodies so that they "
                  "share faces, or remove the part";
    if (part_fixed.empty())
      throw_error(prefix, part, " has no fixed node and can move freely (", fixed_nodes.size(),
                  " node(s) are fixed elsewhere: ", list_nodes(fixed_nodes), ")", fix);

    Eigen::Matrix<double, 6, 6> gram = Eigen::Matrix<double, 6, 6>::Zero();
    for (int i : part_fixed) {
      const Eigen::Vector3d r = (mesh.nodes.row(i).transpose() - centroid) / size;
      for (int c = 0; c < 3; ++c) {
        if (!(fixed.mask(i) & (1u << c))) continue;
        Eigen::Matrix<double, 6, 1> row = Eigen::Matrix<double, 6, 1>::Zero();
        row[c] = 1;
        for (int a = 0; a < 3; ++a) row[3 + a] = Eigen::Vector3d::Unit(a).cross(r)[c];  // (e_a x r)_c
        gram += row * row.transpose();
      }
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eig(gram);
    const double tol = 1e-10 * std::max(1.0, eig.eigenvalues().maxCoeff());
    int free_modes = 0;
    for (int k = 0; k < 6; ++k)
      if (eig.eigenvalues()[k] <= tol) ++free_modes;
    if (free_modes == 0) continue;

    // Describe the first free mode: a translation, or a rotation about an axis.
    const Eigen::Matrix<double, 6, 1> mode = eig.eigenvectors().col(0);
    std::ostringstream what;
    const Eigen::Vector3d w = mode.tail<3>();
    if (w.norm() < 1e-6) {
      what << "a translation along (" << canonical_direction(mode.head<3>()).transpose() << ")";
    } else {
      what << "a rotation about the axis along (" << canonical_direction(w).transpose() << ")";
    }
    std::string shape;
    const bool whole_nodes =
        std::all_of(part_fixed.begin(), part_fixed.end(), [&](int i) { return fixed.mask(i) == 7; });
    if (whole_nodes && part_fixed.size() == 1)
      shape = "a single fixed node";
    else if (whole_nodes)
      shape = "all fixed nodes lie on one line";
    else
      shape = "the fixed components do not hold every rigid motion";
    throw_error(prefix, "the fixed set leaves ", free_modes, " rigid mode(s) of ", part, " free (", shape, "; e.g. ",
                what.str(), "); ", part_fixed.size(), " node(s) fixed there: ", list_nodes(part_fixed), fix);
  }
}

}  // namespace surgsim::fem
