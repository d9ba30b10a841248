// face_components (union-find over tets joined by shared faces, found by sorting the faces' node triples),
// anchored_components, and the compaction behind remove_elements and extract_component.
#include "cut/components.h"

#include <algorithm>
#include <array>
#include <cstddef>
#include <vector>

#include "core/error.h"
#include "core/union_find.h"

namespace surgsim::cut {

namespace {

// Keeps the tets with keep[t] and the nodes they use, in their order.
Compacted keep_elements(const mesh::TetMesh& mesh, const std::vector<char>& keep) {
  Compacted c;
  const auto nv = static_cast<int>(mesh.nodes.rows());
  const auto nt = static_cast<int>(mesh.tets.rows());
  c.node_map.assign(static_cast<std::size_t>(nv), -1);
  c.tet_map.assign(static_cast<std::size_t>(nt), -1);
  int kept_tets = 0;
  for (int t = 0; t < nt; ++t) {
    if (!keep[static_cast<std::size_t>(t)]) continue;
    c.tet_map[static_cast<std::size_t>(t)] = kept_tets++;
    for (int k = 0; k < 4; ++k) c.node_map[static_cast<std::size_t>(mesh.tets(t, k))] = 0;
  }
  int kept_nodes = 0;
  for (int& m : c.node_map) {
    if (m == 0) m = kept_nodes++;
  }
  c.mesh.source = mesh.source;
  c.mesh.nodes.resize(kept_nodes, 3);
  c.mesh.tets.resize(kept_tets, 4);
  for (int i = 0; i < nv; ++i) {
    const int m = c.node_map[static_cast<std::size_t>(i)];
    if (m < 0) continue;
    c.mesh.nodes.row(m) = mesh.nodes.row(i);
    if (!mesh.ids.empty()) c.mesh.ids.push_back(mesh.ids[static_cast<std::size_t>(i)]);
  }
  for (int t = 0; t < nt; ++t) {
    const int m = c.tet_map[static_cast<std::size_t>(t)];
    if (m < 0) continue;
    for (int k = 0; k < 4; ++k) c.mesh.tets(m, k) = c.node_map[static_cast<std::size_t>(mesh.tets(t, k))];
    if (!mesh.tet_ids.empty()) c.mesh.tet_ids.push_back(mesh.tet_ids[static_cast<std::size_t>(t)]);
  }
  return c;
}

}  // namespace

Components face_components(const mesh::TetMesh& mesh) {
  const auto nt = static_cast<int>(mesh.tets.rows());
  struct Face {
    std::array<int, 3> key;
    int tet;
  };
  std::vector<Face> faces;
  faces.reserve(static_cast<std::size_t>(nt) * 4);
  for (int t = 0; t < nt; ++t) {
    for (int f = 0; f < 4; ++f) {
      Face face{{}, t};
      int j = 0;
      for (int k = 0; k < 4; ++k) {
        if (k != f) face.key[static_cast<std::size_t>(j++)] = mesh.tets(t, k);
      }
      std::sort(face.key.begin(), face.key.end());
      faces.push_back(face);
    }
  }
  std::sort(faces.begin(), faces.end(),
            [](const Face& x, const Face& y) { return x.key != y.key ? x.key < y.key : x.tet < y.tet; });
  std::vector<int> parent(static_cast<std::size_t>(nt));
  for (int t = 0; t < nt; ++t) parent[static_cast<std::size_t>(t)] = t;
  for (std::size_t i = 0; i + 1 < faces.size(); ++i) {
    if (faces[i].key != faces[i + 1].key) continue;
    const int a = core::find_root(parent, faces[i].tet), b = core::find_root(parent, faces[i + 1].tet);
    // The lower root wins, so each root is its component's lowest tet.
    if (a != b) parent[static_cast<std::size_t>(std::max(a, b))] = std::min(a, b);
  }
  Components c;
  c.of_tet.assign(static_cast<std::size_t>(nt), -1);
  std::vector<int> number(static_cast<std::size_t>(nt), -1);
  for (int t = 0; t < nt; ++t) {
    const int root = core::find_root(parent, t);
    if (number[static_cast<std::size_t>(root)] < 0) number[static_cast<std::size_t>(root)] = c.count++;
    c.of_tet[static_cast<std::size_t>(t)] = number[static_cast<std::size_t>(root)];
  }
  return c;
}

std::vector<bool> anchored_components(const mesh::TetMesh& mesh, const Components& components,
                                      const std::vector<int>& nodes) {
  const auto nv = static_cast<int>(mesh.nodes.rows());
  std::vector<char> in_set(static_cast<std::size_t>(nv), 0);
  for (const int n : nodes) {
    if (n < 0 || n >= nv) core::throw_error("anchored_components: node ", n, " is not in the mesh (", nv, " nodes)");
    in_set[static_cast<std::size_t>(n)] = 1;
  }
  std::vector<bool> anchored(static_cast<std::size_t>(components.count), false);
  for (int t = 0; t < mesh.tets.rows(); ++t) {
    for (int k = 0; k < 4; ++k) {
      if (in_set[static_cast<std::size_t>(mesh.tets(t, k))]) {
        anchored[static_cast<std::size_t>(components.of_tet[static_cast<std::size_t>(t)])] = true;
      }
    }
  }
  return anchored;
}

Compacted remove_elements(const mesh::TetMesh& mesh, const std::vector<int>& tets) {
  const auto nt = static_cast<int>(mesh.tets.rows());
  std::vector<char> keep(static_cast<std::size_t>(nt), 1);
  for (const int t : tets) {
    if (t < 0 || t >= nt) core::throw_error("remove_elements: tet ", t, " is not in the mesh (", nt, " tets)");
    keep[static_cast<std::size_t>(t)] = 0;
  }
  return keep_elements(mesh, keep);
}

Compacted extract_component(const mesh::TetMesh& mesh, const Components& components, int component) {
  if (component < 0 || component >= components.count) {
    core::throw_error("extract_component: component ", component, " of ", components.count);
  }
  std::vector<char> keep(components.of_tet.size(), 0);
  for (std::size_t t = 0; t < keep.size(); ++t) keep[t] = components.of_tet[t] == component ? 1 : 0;
  return keep_elements(mesh, keep);
}

}  // namespace surgsim::cut
