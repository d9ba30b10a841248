// Gmsh .msh: reading v1, v2 and v4 (4.0, 4.1) ASCII, tetrahedra only; writing v2.2 ASCII.
#include "mesh/mesh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/text.h"
#include "mesh/format_util.h"
#include "mesh/mesh_internal.h"

using namespace surgsim::core;

namespace surgsim::mesh {

using internal::append_number;
using internal::check_indices;
using internal::Cursor;
using internal::iequals;
using internal::printable;
using internal::read_whole_file;
using internal::write_whole_file;

namespace {

struct RawTet {
  std::int64_t id;
  int line;
  std::array<std::int64_t, 4> nodes;
};

// Everything read from a .msh before node ids are resolved (elements may in principle precede nodes).
struct MshData {
  std::vector<double> xyz;        // 3 per node, m
  std::vector<std::int64_t> ids;  // file node ids
  std::vector<int> node_lines;    // where each node was defined
  std::vector<RawTet> tets;
  std::string nodes_tag;  // "$Nodes" or "$NOD", for messages
  bool have_nodes = false;
  bool have_elements = false;

  void reserve_nodes(const Cursor& cur, std::int64_t n) {
    // A declared count is not trusted beyond what the file could hold (garbage must not allocate gigabytes).
    const auto cap = static_cast<std::size_t>(std::min<std::int64_t>(n, static_cast<std::int64_t>(cur.size() / 6)));
    xyz.reserve(xyz.size() + 3 * cap);
    ids.reserve(ids.size() + cap);
    node_lines.reserve(node_lines.size() + cap);
  }

  void add_node(Cursor& cur, std::int64_t id, int line, double x, double y, double z) {
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
      cur.fail_at(line, "node ", id, " has a non-finite coordinate (", x, ", ", y, ", ", z,
                  "): fix the program that wrote the file");
    }
    if (ids.size() >= static_cast<std::size_t>(INT_MAX)) cur.fail_at(line, "too many nodes");
    xyz.push_back(x);
    xyz.push_back(y);
    xyz.push_back(z);
    ids.push_back(id);
    node_lines.push_back(line);
  }
};

// Refuses higher-order tets instead of silently dropping their mid-edge nodes' meaning.
bool keep_gmsh_type(Cursor& cur, std::int64_t type, std::int64_t element_id) {
  if (type == 4) return true;
  if (type == 11 || type == 29 || type == 30 || type == 31) {
    cur.fail("element ", element_id, " is a higher-order tetrahedron (Gmsh type ", type,
             "): only linear tets (type 4) are supported; re-mesh with order 1 (gmsh -3 -order 1)");
  }
  return false;
}

void add_tet(MshData& d, Cursor& cur, std::int64_t id, int line) {
  RawTet t{id, line, {}};
  for (auto& n : t.nodes) n = cur.line_int("node id of a tetrahedron");
  d.tets.push_back(t);
}

void read_msh_format(Cursor& cur, double& version) {
  const std::string_view vt = cur.token();
  version = cur.parse_real(vt, "format version");
  const std::int64_t file_type = cur.line_int("file type (0 = ASCII, 1 = binary)");
  if (file_type == 1) {
    cur.fail("binary .msh not supported: re-save as ASCII with gmsh FILE.msh -save -format msh2 -o OUT.msh");
  }
  if (file_type != 0) cur.fail("file type ", file_type, " in $MeshFormat: expected 0 (ASCII)");
  cur.line_int("data size");
  const bool v2 = version >= 2.0 && version < 3.0;
  const bool v4 = version >= 4.0 && version < 5.0;
  if (!v2 && !v4) {
    cur.fail(".msh version ", printable(vt),
             " is not supported (supported: 1, 2.x, 4.0, 4.1): re-save with "
             "gmsh FILE.msh -save -format msh2 -o OUT.msh");
  }
  cur.expect("$EndMeshFormat", "after the format line");
}

// v1 and v2 nodes: "id x y z" per line.
void read_nodes_v12(Cursor& cur, MshData& d, std::string_view end_tag) {
  const int n = cur.count("number of nodes");
  d.reserve_nodes(cur, n);
  for (int i = 0; i < n; ++i) {
    const std::int64_t id = cur.parse_int(cur.record_start(end_tag, i, n, "node"), "node id");
    const int line = cur.line();
    const double x = cur.line_real("x coordinate");
    const double y = cur.line_real("y coordinate");
    const double z = cur.line_real("z coordinate");
    cur.expect_line_end("a node line (id x y z)");
    d.add_node(cur, id, line, x, y, z);
  }
  cur.expect(end_tag, "after the declared nodes (more nodes than the count says?)");
}

// v1: "id type phys elem n node...".
void read_elements_v1(Cursor& cur, MshData& d) {
  const int n = cur.count("number of elements");
  for (int i = 0; i < n; ++i) {
    const std::int64_t id = cur.parse_int(cur.record_start("$ENDELM", i, n, "element"), "element id");
    const int line = cur.line();
    const std::int64_t type = cur.line_int("element type");
    cur.line_int("physical region");
    cur.line_int("elementary region");
    const std::int64_t nodes = cur.line_int("number of nodes");
    if (keep_gmsh_type(cur, type, id)) {
      if (nodes != 4) cur.fail("element ", id, " is a tetrahedron (type 4) with ", nodes, " nodes: expected 4");
      add_tet(d, cur, id, line);
      cur.expect_line_end("an element line");
    } else {
      cur.skip_line();
    }
  }
  cur.expect("$ENDELM", "after the declared elements (more elements than the count says?)");
}

// v2: "id type ntags tag... node...".
void read_elements_v2(Cursor& cur, MshData& d) {
  const int n = cur.count("number of elements");
  for (int i = 0; i < n; ++i) {
    const std::int64_t id = cur.parse_int(cur.record_start("$EndElements", i, n, "element"), "element id");
    const int line = cur.line();
    const std::int64_t type = cur.line_int("element type");
    const std::int64_t tags = cur.line_int("number of tags");
    if (tags < 0) cur.fail("element ", id, " has a negative number of tags (", tags, ")");
    if (keep_gmsh_type(cur, type, id)) {
      for (std::int64_t k = 0; k < tags; ++k) cur.line_int("element tag");
      add_tet(d, cur, id, line);
      cur.expect_line_end("an element line (id type ntags tags... 4 nodes)");
    } else {
      cur.skip_line();
    }
  }
  cur.expect("$EndElements", "after the declared elements (more elements than the count says?)");
}

// v4: entity blocks. 4.1: "numBlocks numNodes minTag maxTag", then per block "dim entity parametric n",
// n tags, n coordinate lines. 4.0: "numBlocks numNodes", per block "entity dim parametric n", n "tag x y z" lines.
void read_nodes_v4(Cursor& cur, MshData& d, bool v41) {
  const int blocks = cur.count("number of node blocks");
  const int n = cur.count("number of nodes", true);
  if (v41) {
    cur.line_int("minimum node tag");
    cur.line_int("maximum node tag");
  }
  d.reserve_nodes(cur, n);
  std::int64_t read = 0;
  std::vector<std::int64_t> tags;
  std::vector<int> tag_lines;
  for (int b = 0; b < blocks; ++b) {
    const std::string_view first = cur.record_start("$EndNodes", b, blocks, "node block");
    std::int64_t dim = 0;
    if (v41) {
      dim = cur.parse_int(first, "entity dimension");
      cur.line_int("entity tag");
    } else {
      cur.parse_int(first, "entity tag");
      dim = cur.line_int("entity dimension");
    }
    const std::int64_t parametric = cur.line_int("parametric flag");
    const int in_block = cur.count("number of nodes in the block", true);
    if (read + in_block > n) cur.fail("node blocks hold more than the ", n, " nodes declared in the $Nodes header");
    // Parametric nodes carry dim extra coordinates (u, v, w) that are not needed here.
    const std::int64_t extra = parametric ? std::clamp<std::int64_t>(dim, 0, 3) : 0;
    if (v41) {
      tags.clear();
      tag_lines.clear();
      for (int i = 0; i < in_block; ++i) {
        tags.push_back(cur.integer("node tag"));
        tag_lines.push_back(cur.line());
      }
      for (int i = 0; i < in_block; ++i) {
        const double x = cur.real("x coordinate");
        const double y = cur.line_real("y coordinate");
        const double z = cur.line_real("z coordinate");
        for (std::int64_t k = 0; k < extra; ++k) cur.line_real("parametric coordinate");
        cur.expect_line_end("a node coordinate line");
        d.add_node(cur, tags[i], tag_lines[i], x, y, z);
      }
    } else {
      for (int i = 0; i < in_block; ++i) {
        const std::int64_t tag = cur.integer("node tag");
        const int line = cur.line();
        const double x = cur.line_real("x coordinate");
        const double y = cur.line_real("y coordinate");
        const double z = cur.line_real("z coordinate");
        for (std::int64_t k = 0; k < extra; ++k) cur.line_real("parametric coordinate");
        cur.expect_line_end("a node line");
        d.add_node(cur, tag, line, x, y, z);
      }
    }
    read += in_block;
  }
  if (read != n) cur.fail("node blocks hold ", read, " nodes but the $Nodes header declares ", n);
  cur.expect("$EndNodes", "after the declared node blocks (more blocks than the count says?)");
}

// v4 elements: 4.1 "numBlocks numElements minTag maxTag", per block "dim entity type n";
// 4.0 "numBlocks numElements", per block "entity dim type n"; then n lines "tag node...".
void read_elements_v4(Cursor& cur, MshData& d, bool v41) {
  const int blocks = cur.count("number of element blocks");
  const int n = cur.count("number of elements", true);
  if (v41) {
    cur.line_int("minimum element tag");
    cur.line_int("maximum element tag");
  }
  std::int64_t read = 0;
  for (int b = 0; b < blocks; ++b) {
    const std::string_view first = cur.record_start("$EndElements", b, blocks, "element block");
    cur.parse_int(first, v41 ? "entity dimension" : "entity tag");
    cur.line_int(v41 ? "entity tag" : "entity dimension");
    const std::int64_t type = cur.line_int("element type");
    const int in_block = cur.count("number of elements in the block", true);
    if (read + in_block > n) cur.fail("element blocks hold more than the ", n, " elements declared");
    for (int i = 0; i < in_block; ++i) {
      const std::int64_t id = cur.parse_int(cur.record_start("$EndElements", i, in_block, "element"), "element tag");
      const int line = cur.line();
      if (keep_gmsh_type(cur, type, id)) {
        add_tet(d, cur, id, line);
        cur.expect_line_end("a tetrahedron line (tag and 4 node tags)");
      } else {
        cur.skip_line();
      }
    }
    read += in_block;
  }
  if (read != n) cur.fail("element blocks hold ", read, " elements but the $Elements header declares ", n);
  cur.expect("$EndElements", "after the declared element blocks (more blocks than the count says?)");
}

// Sections this reader does not need ($PhysicalNames, $Entities, $NodeData, $Comments, ...).
void skip_section(Cursor& cur, std::string_view tag) {
  const int open_line = cur.line();
  const std::string end = "$End" + std::string(tag.substr(1));
  for (;;) {
    const std::string_view t = cur.token();
    if (t.empty()) {
      cur.fail_at(open_line, "section ", printable(tag), " is never closed (", printable(end), " missing)");
    }
    if (iequals(t, end)) return;
    cur.skip_line();
  }
}

// Node ids to 0-based indices: a table when ids are dense enough, else a hash map.
class IdMap {
 public:
  explicit IdMap(const MshData& d, Cursor& cur) {
    if (d.ids.empty()) return;
    const auto [lo, hi] = std::minmax_element(d.ids.begin(), d.ids.end());
    const std::int64_t n = static_cast<std::int64_t>(d.ids.size());
    dense_ = *lo >= 0 && *hi < 4 * n + 1024;
    if (dense_) table_.assign(static_cast<std::size_t>(*hi) + 1, -1);
    for (std::size_t i = 0; i < d.ids.size(); ++i) {
      const int prev = find(d.ids[i]);
      if (prev >= 0) {
        cur.fail_at(d.node_lines[i], "node ", d.ids[i], " is defined twice (first on line ", d.node_lines[prev],
                    "): node ids must be unique");
      }
      if (dense_) {
        table_[static_cast<std::size_t>(d.ids[i])] = static_cast<int>(i);
      } else {
        map_.emplace(d.ids[i], static_cast<int>(i));
      }
    }
  }

  /// Index of a file id, -1 when unknown.
  int find(std::int64_t id) const {
    if (dense_) return (id >= 0 && static_cast<std::size_t>(id) < table_.size()) ? table_[id] : -1;
    const auto it = map_.find(id);
    return it == map_.end() ? -1 : it->second;
  }

 private:
  bool dense_ = false;
  std::vector<int> table_;
  std::unordered_map<std::int64_t, int> map_;
};

TetMesh resolve_msh(MshData& d, Cursor& cur, const std::string& path) {
  if (!d.have_nodes) throw_error(path, ": no $Nodes (or v1 $NOD) section: not a Gmsh mesh, or an empty file");
  if (!d.have_elements) throw_error(path, ": no $Elements (or v1 $ELM) section: the file holds no elements");
  if (d.tets.empty()) {
    throw_error(path,
                ": no tetrahedra (Gmsh element type 4) among the elements: mesh the volume "
                "(gmsh -3) and save again");
  }
  const IdMap map(d, cur);
  TetMesh mesh;
  mesh.source = path;
  const auto nv = static_cast<Eigen::Index>(d.ids.size());
  mesh.nodes.resize(nv, 3);
  for (Eigen::Index i = 0; i < nv; ++i) {
    for (int c = 0; c < 3; ++c) mesh.nodes(i, c) = d.xyz[static_cast<std::size_t>(3 * i + c)];
  }
  mesh.tets.resize(static_cast<Eigen::Index>(d.tets.size()), 4);
  mesh.tet_ids.reserve(d.tets.size());
  for (std::size_t t = 0; t < d.tets.size(); ++t) {
    const RawTet& r = d.tets[t];
    for (int k = 0; k < 4; ++k) {
      const int v = map.find(r.nodes[k]);
      if (v < 0) {
        cur.fail_at(r.line, "element ", r.id, " references node ", r.nodes[k], " which is not in ", d.nodes_tag);
      }
      mesh.tets(static_cast<Eigen::Index>(t), k) = v;
    }
    mesh.tet_ids.push_back(r.id);
  }
  mesh.ids = std::move(d.ids);
  return mesh;
}

}  // namespace

TetMesh read_msh(const std::string& path) {
  const std::string text = read_whole_file(path);
  if (core::text::trim(text).empty()) throw_error(path, ": empty mesh file");
  Cursor cur(path, text);
  MshData d;
  double version = 1.0;
  bool have_format = false;

  // Sections in any order; unknown ones are skipped to their $End tag.
  for (;;) {
    const std::string_view tag = cur.token();
    if (tag.empty()) break;
    if (tag[0] != '$') {
      cur.fail("expected a section tag such as $MeshFormat, $Nodes or $NOD, got '", printable(tag),
               "': not a Gmsh ASCII mesh");
    }
    if (tag == "$MeshFormat") {
      if (have_format || d.have_nodes) cur.fail("$MeshFormat must come once, before the nodes");
      read_msh_format(cur, version);
      have_format = true;
    } else if (tag == "$NOD" || tag == "$Nodes") {
      const bool v1 = tag == "$NOD";
      if (d.have_nodes) cur.fail("second node section ", tag, ": only one is supported");
      if (v1 && have_format) cur.fail("$NOD (v1) in a file with $MeshFormat ", version, ": expected $Nodes");
      if (!v1 && !have_format) version = 2.2;  // a header-less $Nodes file is read as v2
      d.nodes_tag = std::string(tag);
      if (version >= 4.0) {
        read_nodes_v4(cur, d, version >= 4.05);
      } else {
        read_nodes_v12(cur, d, v1 ? "$ENDNOD" : "$EndNodes");
      }
      d.have_nodes = true;
    } else if (tag == "$ELM" || tag == "$Elements") {
      const bool v1 = tag == "$ELM";
      if (d.have_elements) cur.fail("second element section ", tag, ": only one is supported");
      if (v1 != (d.nodes_tag == "$NOD") && d.have_nodes) {
        cur.fail(tag, " does not match the node section ", d.nodes_tag);
      }
      if (v1) {
        read_elements_v1(cur, d);
      } else if (version >= 4.0) {
        read_elements_v4(cur, d, version >= 4.05);
      } else {
        read_elements_v2(cur, d);
      }
      d.have_elements = true;
    } else if (tag.size() > 1 && !(tag.size() >= 4 && iequals(tag.substr(0, 4), "$End"))) {
      skip_section(cur, tag);
    } else {
      cur.fail("unexpected '", printable(tag), "' outside any section");
    }
  }
  if (d.nodes_tag.empty()) d.nodes_tag = "$Nodes";
  return resolve_msh(d, cur, path);
}

void write_msh(const std::string& path, const TetMesh& mesh) {
  check_indices(mesh, "write_msh");
  // File ids are kept when they are valid Gmsh ids (positive, unique), else nodes and elements are numbered 1..n.
  auto usable = [](const std::vector<std::int64_t>& ids, Eigen::Index n) {
    if (ids.size() != static_cast<std::size_t>(n)) return false;
    std::vector<std::int64_t> s(ids);
    std::sort(s.begin(), s.end());
    return (s.empty() || s.front() > 0) && std::adjacent_find(s.begin(), s.end()) == s.end();
  };
  const bool node_ids = usable(mesh.ids, mesh.nodes.rows());
  const bool tet_ids = usable(mesh.tet_ids, mesh.tets.rows());
  const std::int64_t nv = mesh.nodes.rows(), nt = mesh.tets.rows();
  std::string out;
  out.reserve(static_cast<std::size_t>(nv * 64 + nt * 48 + 256));
  out += "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n";
  append_number(out, nv);
  out += '\n';
  for (Eigen::Index i = 0; i < nv; ++i) {
    append_number(out, node_ids ? mesh.ids[static_cast<std::size_t>(i)] : i + 1);
    for (int c = 0; c < 3; ++c) {
      out += ' ';
      append_number(out, mesh.nodes(i, c));
    }
    out += '\n';
  }
  out += "$EndNodes\n$Elements\n";
  append_number(out, nt);
  out += '\n';
  for (Eigen::Index t = 0; t < nt; ++t) {
    append_number(out, tet_ids ? mesh.tet_ids[static_cast<std::size_t>(t)] : t + 1);
    out += " 4 2 1 1";  // tetrahedron, 2 tags: physical group 1, elementary entity 1
    for (int k = 0; k < 4; ++k) {
      const int v = mesh.tets(t, k);
      out += ' ';
      append_number(out, node_ids ? mesh.ids[static_cast<std::size_t>(v)] : static_cast<std::int64_t>(v) + 1);
    }
    out += '\n';
  }
  out += "$EndElements\n";
  write_whole_file(path, out);
}

}  // namespace surgsim::mesh
