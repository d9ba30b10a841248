// Tetrahedral mesh I/O (Gmsh .msh v1/v2/v4 ASCII, VTK legacy ASCII), boundary extraction, validation, hashing.
#include "mesh/mesh.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string_view>
#include <tuple>
#include <unordered_map>
#include <utility>

#include "core/error.h"
#include "core/hash.h"

namespace surgsim {
namespace {

// ------------------------------------------------------------------------------------------------------------
// Text helpers

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v'; }

bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  }
  return true;
}

// Garbage input ends up in messages: keep them one short printable line.
std::string printable(std::string_view s) {
  constexpr std::size_t kMax = 40;
  std::string out;
  for (char c : s.substr(0, kMax)) out += (c >= 0x20 && c < 0x7f) ? c : '?';
  if (s.size() > kMax) out += "...";
  return out;
}

std::string mesh_name(const TetMesh& mesh) { return mesh.source.empty() ? "<in-memory mesh>" : mesh.source; }

// Messages name nodes and tets by their file ids when the mesh came from a file.
std::string node_name(const TetMesh& mesh, int i) {
  if (i >= 0 && static_cast<std::size_t>(i) < mesh.ids.size()) return "node " + std::to_string(mesh.ids[i]);
  return "node index " + std::to_string(i);
}

std::string tet_name(const TetMesh& mesh, int t) {
  if (t >= 0 && static_cast<std::size_t>(t) < mesh.tet_ids.size()) return "element " + std::to_string(mesh.tet_ids[t]);
  return "tet " + std::to_string(t) + " (0-based)";
}

std::string tet_nodes_text(const TetMesh& mesh, const Eigen::MatrixX4i& tets, int t) {
  std::string s = " (nodes";
  for (int k = 0; k < 4; ++k) {
    const int v = tets(t, k);
    s += ' ';
    s += (v >= 0 && v < mesh.nodes.rows() && static_cast<std::size_t>(v) < mesh.ids.size())
             ? std::to_string(mesh.ids[v])
             : std::to_string(v);
  }
  return s + ")";
}

std::string read_whole_file(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) throw_error(path, ": cannot open mesh file: ", std::strerror(errno));
  std::string text;
  char buf[1 << 16];
  std::size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) text.append(buf, n);
  const bool failed = std::ferror(f) != 0;
  const int err = errno;
  std::fclose(f);
  if (failed) throw_error(path, ": cannot read mesh file: ", std::strerror(err));
  return text;
}

void write_whole_file(const std::string& path, const std::string& text) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) throw_error(path, ": cannot open for writing: ", std::strerror(errno));
  const bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
  const int err = errno;
  if (std::fclose(f) != 0 || !ok) throw_error(path, ": cannot write: ", std::strerror(ok ? errno : err));
}

void append_number(std::string& out, double v) {
  char buf[64];
  // Shortest representation that reads back to the same double.
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

void append_number(std::string& out, std::int64_t v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

// ------------------------------------------------------------------------------------------------------------
// Cursor: whitespace-separated tokens over a whole file in memory, with line numbers for messages.
// Record-oriented formats read a record's first token with token() (which may cross lines) and its other
// fields with the line_* variants, which refuse to run into the next line.

class Cursor {
 public:
  Cursor(const std::string& path, std::string_view text) : path_(path), text_(text) {}

  /// Next token, crossing line ends; empty at end of file.
  std::string_view token() {
    skip_space(true);
    token_line_ = line_;
    const std::size_t begin = pos_;
    while (pos_ < text_.size() && !is_space(text_[pos_])) ++pos_;
    return text_.substr(begin, pos_ - begin);
  }

  /// The next token without consuming it.
  std::string_view peek() {
    const std::size_t pos = pos_;
    const int line = line_, token_line = token_line_;
    const std::string_view t = token();
    pos_ = pos;
    line_ = line;
    token_line_ = token_line;
    return t;
  }

  /// True when only blanks remain on the current line.
  bool at_line_end() {
    skip_space(false);
    return pos_ >= text_.size() || text_[pos_] == '\n';
  }

  /// The rest of the current line (without '\r'), moving to the start of the next one.
  std::string_view rest_of_line() {
    token_line_ = line_;
    const std::size_t begin = pos_;
    while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
    std::string_view s = text_.substr(begin, pos_ - begin);
    if (pos_ < text_.size()) {
      ++pos_;
      ++line_;
    }
    while (!s.empty() && s.back() == '\r') s.remove_suffix(1);
    return s;
  }

  /// Skips the rest of the current line (the next token() starts on a later line).
  void skip_line() {
    while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
  }

  int line() const { return token_line_; }
  std::size_t size() const { return text_.size(); }

  template <typename... Args>
  [[noreturn]] void fail(const Args&... args) const {
    throw_error(path_, ":", token_line_, ": ", args...);
  }

  template <typename... Args>
  [[noreturn]] void fail_at(int line, const Args&... args) const {
    throw_error(path_, ":", line, ": ", args...);
  }

  [[noreturn]] void fail_eof(std::string_view what) {
    skip_space(true);
    // Report the last line that holds text.
    token_line_ = (!text_.empty() && text_.back() == '\n') ? std::max(1, line_ - 1) : line_;
    fail("unexpected end of file while reading ", what, ": the file is truncated");
  }

  std::int64_t parse_int(std::string_view t, std::string_view what) {
    if (t.empty()) fail_eof(what);
    check_not_section(t, what);
    const char* b = t.data();
    const char* e = t.data() + t.size();
    if (*b == '+') ++b;
    std::int64_t v = 0;
    const auto r = std::from_chars(b, e, v);
    if (r.ec != std::errc() || r.ptr != e) {
      fail("expected an integer (", what, "), got '", printable(t), "'", keyword_hint(t));
    }
    return v;
  }

  double parse_real(std::string_view t, std::string_view what) {
    if (t.empty()) fail_eof(what);
    check_not_section(t, what);
    const char* b = t.data();
    const char* e = t.data() + t.size();
    if (*b == '+') ++b;
    double v = 0;
    const auto r = std::from_chars(b, e, v);
    if (r.ec != std::errc() || r.ptr != e) {
      fail("expected a number (", what, "), got '", printable(t), "'", keyword_hint(t));
    }
    return v;
  }

  std::int64_t integer(std::string_view what) { return parse_int(token(), what); }
  double real(std::string_view what) { return parse_real(token(), what); }

  /// A field that must be on the current line.
  std::int64_t line_int(std::string_view what) {
    if (at_line_end()) fail("line ends early: missing ", what);
    return integer(what);
  }
  double line_real(std::string_view what) {
    if (at_line_end()) fail("line ends early: missing ", what);
    return real(what);
  }

  /// A non-negative count that fits an int (node and element indices are ints).
  int count(std::string_view what, bool on_line = false) {
    const std::int64_t v = on_line ? line_int(what) : integer(what);
    if (v < 0 || v > INT_MAX) fail(what, " is ", v, ": expected a count between 0 and ", INT_MAX);
    return static_cast<int>(v);
  }

  void expect_line_end(std::string_view record) {
    if (!at_line_end()) {
      const std::string_view extra = token();
      fail("unexpected extra value '", printable(extra), "' at the end of ", record);
    }
  }

  /// The first token of record i of n in a section that must end with end_tag.
  std::string_view record_start(std::string_view end_tag, std::int64_t i, std::int64_t n, std::string_view what) {
    const std::string_view t = token();
    if (t.empty()) {
      fail_eof(std::string(what) + " " + std::to_string(i + 1) + " of " + std::to_string(n) + " (" +
               std::string(end_tag) + " missing)");
    }
    if (t[0] == '$') {
      fail("'", printable(t), "' after ", i, " of ", n, " declared ", what,
           "s: the section is shorter than its header says (truncated or edited file?)");
    }
    return t;
  }

  void expect(std::string_view keyword, std::string_view context) {
    const std::string_view t = token();
    if (t.empty()) fail_eof(std::string(keyword) + " " + std::string(context));
    if (!iequals(t, keyword)) fail("expected ", keyword, " ", context, ", got '", printable(t), "'");
  }

 private:
  void skip_space(bool cross_lines) {
    while (pos_ < text_.size() && is_space(text_[pos_])) {
      if (text_[pos_] == '\n') {
        if (!cross_lines) return;
        ++line_;
      }
      ++pos_;
    }
  }

  // A VTK keyword where a number belongs means the previous section is shorter than declared.
  static const char* keyword_hint(std::string_view t) {
    const bool keyword =
        t.size() > 3 && std::all_of(t.begin(), t.end(), [](char c) { return (c >= 'A' && c <= 'Z') || c == '_'; });
    return keyword ? ": a keyword, so the section before it holds fewer values than its header declares" : "";
  }

  // A section tag where a number belongs means the counts and the data disagree.
  void check_not_section(std::string_view t, std::string_view what) {
    if (t[0] == '$') {
      fail("unexpected '", printable(t), "' while reading ", what,
           ": the section holds fewer entries than its header declares (truncated or edited file?)");
    }
  }

  std::string path_;
  std::string_view text_;
  std::size_t pos_ = 0;
  int line_ = 1;
  int token_line_ = 1;
};

// ------------------------------------------------------------------------------------------------------------
// Gmsh .msh

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

// ------------------------------------------------------------------------------------------------------------
// Faces and edges

struct Face {
  std::array<int, 3> key;  // sorted node indices
  int tet;
  int local;  // index of the opposite vertex in the tet
};

// All tet faces sorted by key, so that equal faces are adjacent.
std::vector<Face> sorted_faces(const Eigen::MatrixX4i& tets) {
  std::vector<Face> faces;
  faces.reserve(static_cast<std::size_t>(tets.rows()) * 4);
  for (int t = 0; t < tets.rows(); ++t) {
    for (int f = 0; f < 4; ++f) {
      Face face{{}, t, f};
      int j = 0;
      for (int k = 0; k < 4; ++k) {
        if (k != f) face.key[j++] = tets(t, k);
      }
      std::sort(face.key.begin(), face.key.end());
      faces.push_back(face);
    }
  }
  std::sort(faces.begin(), faces.end(), [](const Face& a, const Face& b) {
    return std::tie(a.key, a.tet, a.local) < std::tie(b.key, b.tet, b.local);
  });
  return faces;
}

// Face of tet t opposite vertex f, oriented so that its normal points away from that vertex.
std::array<int, 3> outward_face(const Eigen::MatrixX3d& nodes, const Eigen::MatrixX4i& tets, int t, int f) {
  std::array<int, 3> tri{};
  int j = 0;
  for (int k = 0; k < 4; ++k) {
    if (k != f) tri[j++] = tets(t, k);
  }
  const Eigen::Vector3d a = nodes.row(tri[0]).transpose();
  const Eigen::Vector3d b = nodes.row(tri[1]).transpose();
  const Eigen::Vector3d c = nodes.row(tri[2]).transpose();
  const Eigen::Vector3d d = nodes.row(tets(t, f)).transpose();
  if ((b - a).cross(c - a).dot(d - a) > 0) std::swap(tri[1], tri[2]);
  return tri;
}

void check_indices(const TetMesh& mesh, const char* caller) {
  const auto nv = mesh.nodes.rows();
  for (int t = 0; t < mesh.tets.rows(); ++t) {
    for (int k = 0; k < 4; ++k) {
      const int v = mesh.tets(t, k);
      if (v < 0 || v >= nv) {
        throw_error(mesh_name(mesh), ": ", tet_name(mesh, t), " references node index ", v, " but the mesh has ", nv,
                    " nodes (", caller, "): call validate_mesh first");
      }
    }
  }
}

}  // namespace

// --------------------------------------------------------------------------------------------------------------
// Reading

TetMesh read_msh(const std::string& path) {
  const std::string text = read_whole_file(path);
  if (text.find_first_not_of(" \t\r\n") == std::string::npos) throw_error(path, ": empty mesh file");
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

TetMesh read_vtk(const std::string& path) {
  const std::string text = read_whole_file(path);
  if (text.find_first_not_of(" \t\r\n") == std::string::npos) throw_error(path, ": empty mesh file");
  Cursor cur(path, text);

  // Header: version line, title line, ASCII/BINARY, DATASET type.
  const std::string_view first = cur.rest_of_line();
  if (first.size() < 5 || !iequals(first.substr(0, 5), "# vtk")) {
    cur.fail("not a VTK legacy file: the first line must be '# vtk DataFile Version ...', got '", printable(first),
             "'");
  }
  cur.rest_of_line();  // title
  const std::string_view format = cur.token();
  if (iequals(format, "BINARY")) {
    cur.fail(
        "binary VTK not supported: save as ASCII (e.g. ParaView Save Data with File Type ASCII, or meshio "
        "with binary=False)");
  }
  if (!iequals(format, "ASCII")) cur.fail("expected ASCII or BINARY on line 3, got '", printable(format), "'");
  cur.expect("DATASET", "after ASCII");
  const std::string_view dataset = cur.token();
  if (!iequals(dataset, "UNSTRUCTURED_GRID")) {
    cur.fail("DATASET '", printable(dataset), "' is not supported: only UNSTRUCTURED_GRID (tetrahedra, cell type 10)");
  }

  std::vector<double> xyz;
  std::vector<int> point_lines;
  std::vector<std::int64_t> conn;     // all cells' point indices
  std::vector<int> conn_lines;        // where each index was read
  std::vector<std::int64_t> offsets;  // #cells + 1 into conn
  std::vector<int> cell_lines;
  std::vector<std::int64_t> types;
  int types_line = 0;
  bool have_points = false, have_cells = false, have_types = false;

  // Sections until the (ignored) attribute data.
  for (;;) {
    const std::string_view kw = cur.token();
    if (kw.empty()) break;
    if (iequals(kw, "POINTS")) {
      if (have_points) cur.fail("second POINTS section");
      const int n = cur.count("number of points", true);
      const std::string_view type = cur.token();
      static const char* const kTypes[] = {"float", "double", "int", "long", "short", "vtktypeint64", "vtktypeint32"};
      if (std::none_of(std::begin(kTypes), std::end(kTypes), [&](const char* t) { return iequals(type, t); })) {
        cur.fail("unsupported POINTS data type '", printable(type), "': expected float or double");
      }
      xyz.reserve(3 * static_cast<std::size_t>(std::min<std::int64_t>(n, static_cast<std::int64_t>(text.size() / 6))));
      for (int i = 0; i < n; ++i) {
        for (int c = 0; c < 3; ++c) {
          const double v = cur.real("point coordinate");
          if (c == 0) point_lines.push_back(cur.line());
          if (!std::isfinite(v)) cur.fail("point ", i, " has a non-finite coordinate: fix the program that wrote it");
          xyz.push_back(v);
        }
      }
      have_points = true;
    } else if (iequals(kw, "CELLS")) {
      if (have_cells) cur.fail("second CELLS section");
      const int n = cur.count("number of cells", true);
      const int size = cur.count("size of the cell list", true);
      const auto cap =
          static_cast<std::size_t>(std::min<std::int64_t>(size, static_cast<std::int64_t>(text.size() / 2)));
      conn.reserve(cap);
      if (iequals(cur.peek(), "OFFSETS")) {
        // VTK 5.1: "CELLS #offsets #connectivity", OFFSETS type, offsets, CONNECTIVITY type, indices.
        cur.token();
        cur.token();
        for (int i = 0; i < n; ++i) {
          offsets.push_back(cur.integer("cell offset"));
          cell_lines.push_back(cur.line());
          if (offsets.back() < 0 || offsets.back() > size || (i > 0 && offsets.back() < offsets[i - 1]) ||
              (i == 0 && offsets.back() != 0)) {
            cur.fail("cell offset ", offsets.back(), " is out of order or outside 0..", size);
          }
        }
        if (n > 0 && offsets.back() != size) cur.fail("last cell offset ", offsets.back(), " differs from ", size);
        cur.expect("CONNECTIVITY", "after the cell offsets");
        cur.token();
        for (int i = 0; i < size; ++i) {
          conn.push_back(cur.integer("cell point index"));
          conn_lines.push_back(cur.line());
        }
        if (!cell_lines.empty()) cell_lines.pop_back();  // one line per cell, not per offset
        if (n == 0) offsets.push_back(0);
      } else {
        // Legacy: n cells "k i1 .. ik", size = total integer count.
        offsets.push_back(0);
        std::int64_t used = 0;
        for (int i = 0; i < n; ++i) {
          const std::int64_t k = cur.integer("cell point count");
          cell_lines.push_back(cur.line());
          used += k + 1;
          if (k < 0 || used > size) cur.fail("cell ", i, " with ", k, " points overruns the CELLS size ", size);
          for (std::int64_t j = 0; j < k; ++j) {
            conn.push_back(cur.integer("cell point index"));
            conn_lines.push_back(cur.line());
          }
          offsets.push_back(static_cast<std::int64_t>(conn.size()));
        }
        if (used != size) cur.fail("CELLS declares size ", size, " but its cells hold ", used, " values");
      }
      have_cells = true;
    } else if (iequals(kw, "CELL_TYPES")) {
      if (have_types) cur.fail("second CELL_TYPES section");
      const int n = cur.count("number of cell types", true);
      types_line = cur.line();
      types.reserve(static_cast<std::size_t>(std::min<std::int64_t>(n, static_cast<std::int64_t>(text.size() / 2))));
      for (int i = 0; i < n; ++i) types.push_back(cur.integer("cell type"));
      have_types = true;
    } else if (iequals(kw, "METADATA")) {
      // VTK 5.1 metadata block: runs to the next empty line.
      cur.rest_of_line();
      while (cur.rest_of_line().find_first_not_of(" \t") != std::string_view::npos) {
      }
    } else if (iequals(kw, "POINT_DATA") || iequals(kw, "CELL_DATA") || iequals(kw, "FIELD")) {
      break;  // attributes are not part of the mesh
    } else {
      cur.fail("unexpected keyword '", printable(kw), "' in an UNSTRUCTURED_GRID (expected POINTS, CELLS, CELL_TYPES)");
    }
  }
  if (!have_points) throw_error(path, ": no POINTS section");
  if (!have_cells) throw_error(path, ": no CELLS section");
  if (!have_types) throw_error(path, ": no CELL_TYPES section");
  const int ncells = static_cast<int>(offsets.size()) - 1;
  if (static_cast<int>(types.size()) != ncells) {
    cur.fail_at(types_line, "CELL_TYPES lists ", types.size(), " types for ", ncells, " cells");
  }

  // Keep tetra (type 10); refuse quadratic tetra (24); skip the rest.
  TetMesh mesh;
  mesh.source = path;
  const auto nv = static_cast<Eigen::Index>(xyz.size() / 3);
  mesh.nodes.resize(nv, 3);
  for (Eigen::Index i = 0; i < nv; ++i) {
    for (int c = 0; c < 3; ++c) mesh.nodes(i, c) = xyz[static_cast<std::size_t>(3 * i + c)];
  }
  std::vector<std::array<int, 4>> tets;
  for (int c = 0; c < ncells; ++c) {
    const int line = cell_lines[static_cast<std::size_t>(c)];
    if (types[c] == 24) {
      cur.fail_at(line, "cell ", c, " is a quadratic tetrahedron (type 24): only linear tets (type 10) are supported");
    }
    if (types[c] != 10) continue;
    const std::int64_t b = offsets[c], e = offsets[c + 1];
    if (e - b != 4) cur.fail_at(line, "cell ", c, " is a tetrahedron (type 10) with ", e - b, " points: expected 4");
    std::array<int, 4> tet{};
    for (int k = 0; k < 4; ++k) {
      const std::int64_t p = conn[static_cast<std::size_t>(b + k)];
      if (p < 0 || p >= nv) {
        cur.fail_at(conn_lines[static_cast<std::size_t>(b + k)], "cell ", c, " references point ", p,
                    " but POINTS has ", nv, " points (0-based indices)");
      }
      tet[k] = static_cast<int>(p);
    }
    tets.push_back(tet);
    mesh.tet_ids.push_back(c);
  }
  if (tets.empty()) throw_error(path, ": no tetrahedra (VTK cell type 10) among the ", ncells, " cells");
  mesh.tets.resize(static_cast<Eigen::Index>(tets.size()), 4);
  for (std::size_t t = 0; t < tets.size(); ++t) {
    for (int k = 0; k < 4; ++k) mesh.tets(static_cast<Eigen::Index>(t), k) = tets[t][k];
  }
  // VTK has no ids: the 0-based point index is what the file calls a node.
  mesh.ids.resize(static_cast<std::size_t>(nv));
  for (Eigen::Index i = 0; i < nv; ++i) mesh.ids[static_cast<std::size_t>(i)] = i;
  return mesh;
}

TetMesh read_mesh(const std::string& path) {
  const std::size_t slash = path.find_last_of("/\\");
  const std::size_t dot = path.find_last_of('.');
  std::string ext = (dot == std::string::npos || (slash != std::string::npos && dot < slash)) ? "" : path.substr(dot);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".msh") return read_msh(path);
  if (ext == ".vtk") return read_vtk(path);
  throw_error(path, ": unsupported mesh file extension '", ext,
              "': supported are .msh (Gmsh v1, v2, v4 ASCII) and .vtk (VTK legacy ASCII unstructured grid)");
}

// --------------------------------------------------------------------------------------------------------------
// Writing

void write_vtk(const std::string& path, const TetMesh& mesh, const Eigen::MatrixX3d* node_vectors,
               const std::string& vector_name) {
  check_indices(mesh, "write_vtk");
  if (node_vectors && node_vectors->rows() != mesh.nodes.rows()) {
    throw_error(path, ": node vector field '", vector_name, "' has ", node_vectors->rows(), " rows for ",
                mesh.nodes.rows(), " nodes");
  }
  if (node_vectors && (vector_name.empty() || std::any_of(vector_name.begin(), vector_name.end(), is_space))) {
    throw_error(path, ": VTK field name '", vector_name, "' must be non-empty and contain no spaces");
  }
  const std::int64_t nv = mesh.nodes.rows(), nt = mesh.tets.rows();
  std::string out;
  out.reserve(static_cast<std::size_t>(nv * 60 + nt * 40 + 256));
  out += "# vtk DataFile Version 3.0\nsurgsim tetrahedral mesh\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS ";
  append_number(out, nv);
  out += " double\n";
  auto append_rows = [&out](const Eigen::MatrixX3d& m) {
    for (Eigen::Index i = 0; i < m.rows(); ++i) {
      for (int c = 0; c < 3; ++c) {
        if (c) out += ' ';
        append_number(out, m(i, c));
      }
      out += '\n';
    }
  };
  append_rows(mesh.nodes);
  out += "CELLS ";
  append_number(out, nt);
  out += ' ';
  append_number(out, 5 * nt);
  out += '\n';
  for (Eigen::Index t = 0; t < nt; ++t) {
    out += '4';
    for (int k = 0; k < 4; ++k) {
      out += ' ';
      append_number(out, static_cast<std::int64_t>(mesh.tets(t, k)));
    }
    out += '\n';
  }
  out += "CELL_TYPES ";
  append_number(out, nt);
  out += '\n';
  for (Eigen::Index t = 0; t < nt; ++t) out += "10\n";
  if (node_vectors) {
    out += "POINT_DATA ";
    append_number(out, nv);
    out += "\nVECTORS " + vector_name + " double\n";
    append_rows(*node_vectors);
  }
  write_whole_file(path, out);
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

// --------------------------------------------------------------------------------------------------------------
// Geometry and checks

double tet_volume(const TetMesh& mesh, int t) {
  const Eigen::Vector3d x0 = mesh.nodes.row(mesh.tets(t, 0)).transpose();
  const Eigen::Vector3d x1 = mesh.nodes.row(mesh.tets(t, 1)).transpose();
  const Eigen::Vector3d x2 = mesh.nodes.row(mesh.tets(t, 2)).transpose();
  const Eigen::Vector3d x3 = mesh.nodes.row(mesh.tets(t, 3)).transpose();
  return (x1 - x0).dot((x2 - x0).cross(x3 - x0)) / 6.0;
}

double tet_quality(const TetMesh& mesh, int t) {
  double sum = 0;
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b) sum += (mesh.nodes.row(mesh.tets(t, a)) - mesh.nodes.row(mesh.tets(t, b))).squaredNorm();
  const double l_rms = std::sqrt(sum / 6);
  return l_rms > 0 ? 6 * std::sqrt(2.0) * std::abs(tet_volume(mesh, t)) / (l_rms * l_rms * l_rms) : 0.0;
}

SurfaceMesh boundary_surface(const TetMesh& mesh) {
  check_indices(mesh, "boundary_surface");
  const std::vector<Face> faces = sorted_faces(mesh.tets);
  // A face met once belongs to one tet only: it is on the boundary.
  std::vector<std::pair<int, int>> owners;  // (tet, local face), in tet order
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i + 1;
    while (j < faces.size() && faces[j].key == faces[i].key) ++j;
    if (j - i == 1) owners.emplace_back(faces[i].tet, faces[i].local);
    i = j;
  }
  std::sort(owners.begin(), owners.end());
  SurfaceMesh s;
  s.tris.resize(static_cast<Eigen::Index>(owners.size()), 3);
  for (std::size_t f = 0; f < owners.size(); ++f) {
    const std::array<int, 3> tri = outward_face(mesh.nodes, mesh.tets, owners[f].first, owners[f].second);
    for (int k = 0; k < 3; ++k) {
      s.tris(static_cast<Eigen::Index>(f), k) = tri[k];
      s.nodes.push_back(tri[k]);
    }
  }
  std::sort(s.nodes.begin(), s.nodes.end());
  s.nodes.erase(std::unique(s.nodes.begin(), s.nodes.end()), s.nodes.end());
  return s;
}

void validate_mesh(TetMesh& mesh, const MeshValidation& opts) {
  const std::string file = mesh_name(mesh);
  const auto nv = static_cast<int>(mesh.nodes.rows());
  const auto nt = static_cast<int>(mesh.tets.rows());
  if (nt == 0) throw_error(file, ": the mesh has no tetrahedra: mesh the volume, not only its surface");
  if (!mesh.ids.empty() && mesh.ids.size() != static_cast<std::size_t>(nv)) {
    throw_error(file, ": ", mesh.ids.size(), " node ids for ", nv, " nodes: ids must be empty or one per node");
  }
  if (!mesh.tet_ids.empty() && mesh.tet_ids.size() != static_cast<std::size_t>(nt)) {
    throw_error(file, ": ", mesh.tet_ids.size(), " element ids for ", nt,
                " tets: tet_ids must be empty or one per tet");
  }

  // Coordinates.
  for (int i = 0; i < nv; ++i) {
    if (!mesh.nodes.row(i).allFinite()) {
      throw_error(file, ": ", node_name(mesh, i), " has a non-finite coordinate (", mesh.nodes(i, 0), ", ",
                  mesh.nodes(i, 1), ", ", mesh.nodes(i, 2), "): fix the file or the program that generated it");
    }
  }

  // Connectivity of each tet.
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 4; ++k) {
      const int v = mesh.tets(t, k);
      if (v < 0 || v >= nv) {
        throw_error(file, ": ", tet_name(mesh, t), " references node index ", v, " but the mesh has ", nv,
                    " nodes (valid 0..", nv - 1, "): the element list does not match the node list");
      }
    }
    for (int a = 0; a < 4; ++a) {
      for (int b = a + 1; b < 4; ++b) {
        if (mesh.tets(t, a) == mesh.tets(t, b)) {
          throw_error(file, ": ", tet_name(mesh, t), tet_nodes_text(mesh, mesh.tets, t), " uses ",
                      node_name(mesh, mesh.tets(t, a)), " twice: remove the collapsed element or re-mesh");
        }
      }
    }
  }

  // Volumes: degenerate tets are refused; inverted ones are flipped (on a copy, committed only on success).
  std::vector<double> vol(static_cast<std::size_t>(nt));
  double mean = 0;
  for (int t = 0; t < nt; ++t) {
    vol[t] = tet_volume(mesh, t);
    mean += std::abs(vol[t]);
  }
  mean /= nt;
  Eigen::MatrixX4i tets = mesh.tets;
  for (int t = 0; t < nt; ++t) {
    if (vol[t] == 0 || std::abs(vol[t]) < opts.min_volume_ratio * mean) {
      throw_error(file, ": ", tet_name(mesh, t), tet_nodes_text(mesh, tets, t), " has zero volume (", vol[t],
                  " m^3, mean ", mean,
                  " m^3): remove the flat element or re-mesh with quality optimization "
                  "(e.g. gmsh -3 -optimize_netgen)");
    }
    if (vol[t] < 0) {
      if (!opts.fix_orientation) {
        throw_error(file, ": ", tet_name(mesh, t), tet_nodes_text(mesh, tets, t), " is inverted (volume ", vol[t],
                    " m^3): its node order is reversed; set fix_orientation or swap two of its nodes");
      }
      std::swap(tets(t, 1), tets(t, 2));
    }
  }

  // Every node belongs to some tet (a stray node would get no stiffness and make K singular).
  std::vector<char> used(static_cast<std::size_t>(nv), 0);
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 4; ++k) used[tets(t, k)] = 1;
  }
  const auto unused = std::count(used.begin(), used.end(), 0);
  if (unused > 0) {
    const int first = static_cast<int>(std::find(used.begin(), used.end(), 0) - used.begin());
    throw_error(file, ": ", node_name(mesh, first), " is not used by any tetrahedron (", unused,
                " unused node(s) in all): remove them, e.g. export only the volume mesh");
  }

  // Each face belongs to one or two tets.
  const std::vector<Face> faces = sorted_faces(tets);
  std::vector<std::array<int, 3>> boundary;
  std::vector<int> boundary_tet;
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i + 1;
    while (j < faces.size() && faces[j].key == faces[i].key) ++j;
    if (j - i > 2) {
      const auto& k = faces[i].key;
      throw_error(file, ": the face (", node_name(mesh, k[0]), ", ", node_name(mesh, k[1]), ", ", node_name(mesh, k[2]),
                  ") is shared by ", j - i, " tets, e.g. ", tet_name(mesh, faces[i].tet), " and ",
                  tet_name(mesh, faces[i + 2].tet), ": overlapping or duplicated elements; re-mesh");
    }
    if (j - i == 1) {
      boundary.push_back(faces[i].key);
      boundary_tet.push_back(faces[i].tet);
    }
    i = j;
  }

  // Each boundary edge belongs to exactly two boundary faces (a closed 2-manifold surface).
  struct Edge {
    int a, b, face;
  };
  std::vector<Edge> edges;
  edges.reserve(boundary.size() * 3);
  for (std::size_t f = 0; f < boundary.size(); ++f) {
    const auto& k = boundary[f];  // sorted, so each pair is (low, high)
    edges.push_back({k[0], k[1], static_cast<int>(f)});
    edges.push_back({k[0], k[2], static_cast<int>(f)});
    edges.push_back({k[1], k[2], static_cast<int>(f)});
  }
  std::sort(edges.begin(), edges.end(),
            [](const Edge& x, const Edge& y) { return std::tie(x.a, x.b, x.face) < std::tie(y.a, y.b, y.face); });
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i + 1;
    while (j < edges.size() && edges[j].a == edges[i].a && edges[j].b == edges[i].b) ++j;
    if (j - i != 2) {
      throw_error(file, ": the boundary edge (", node_name(mesh, edges[i].a), ", ", node_name(mesh, edges[i].b),
                  ") belongs to ", j - i, " boundary faces instead of 2, e.g. a face of ",
                  tet_name(mesh, boundary_tet[edges[i].face]),
                  ": the surface is non-manifold there (tets touching along an edge only); re-mesh or remove the "
                  "dangling elements");
    }
    i = j;
  }
  mesh.tets = std::move(tets);
}

std::uint64_t mesh_hash(const TetMesh& mesh) {
  Hasher h;
  h.value<std::uint64_t>(static_cast<std::uint64_t>(mesh.nodes.rows()));
  for (Eigen::Index i = 0; i < mesh.nodes.rows(); ++i) {
    for (int c = 0; c < 3; ++c) {
      // +0 and -0 compare equal, so they hash equal.
      const double v = mesh.nodes(i, c) == 0.0 ? 0.0 : mesh.nodes(i, c);
      h.value(v);
    }
  }
  h.value<std::uint64_t>(static_cast<std::uint64_t>(mesh.tets.rows()));
  for (Eigen::Index t = 0; t < mesh.tets.rows(); ++t) {
    for (int k = 0; k < 4; ++k) h.value<std::int32_t>(mesh.tets(t, k));
  }
  return h.digest();
}

void write_vtk_surface(const std::string& path, const Eigen::MatrixX3d& points, const Eigen::MatrixX3i& tris) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) throw_error(path, ": cannot create the VTK file (check that its folder exists and is writable)");
  std::fprintf(f, "# vtk DataFile Version 3.0\nsurgsim surface\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS %ld double\n",
               static_cast<long>(points.rows()));
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    std::fprintf(f, "%.9g %.9g %.9g\n", points(i, 0), points(i, 1), points(i, 2));
  }
  std::fprintf(f, "CELLS %ld %ld\n", static_cast<long>(tris.rows()), static_cast<long>(4 * tris.rows()));
  for (Eigen::Index i = 0; i < tris.rows(); ++i) std::fprintf(f, "3 %d %d %d\n", tris(i, 0), tris(i, 1), tris(i, 2));
  std::fprintf(f, "CELL_TYPES %ld\n", static_cast<long>(tris.rows()));
  for (Eigen::Index i = 0; i < tris.rows(); ++i) std::fprintf(f, "5\n");
  const bool ok = std::ferror(f) == 0;
  if (std::fclose(f) != 0 || !ok) throw_error(path, ": write failed");
}

TriSurface read_obj(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "r");
  if (f == nullptr) throw_error(path, ": cannot open the surface file");
  TriSurface out;
  out.source = path;
  std::vector<Eigen::Vector3d> verts;
  std::vector<Eigen::Vector3i> tris;
  char buf[4096];
  long line = 0;
  auto fail = [&](const std::string& what) {
    std::fclose(f);
    throw_error(path, ":", line, ": ", what);
  };
  while (std::fgets(buf, sizeof buf, f) != nullptr) {
    ++line;
    const char* p = buf;
    while (*p == ' ' || *p == '\t') ++p;
    if (p[0] == 'v' && (p[1] == ' ' || p[1] == '\t')) {
      double x, y, z;
      if (std::sscanf(p + 2, "%lf %lf %lf", &x, &y, &z) != 3) fail("a vertex needs three numbers (v x y z)");
      if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) fail("non-finite vertex coordinate");
      verts.emplace_back(x, y, z);
    } else if (p[0] == 'f' && (p[1] == ' ' || p[1] == '\t')) {
      std::vector<int> poly;
      const char* q = p + 2;
      while (*q != '\0' && *q != '\n' && *q != '\r') {
        while (*q == ' ' || *q == '\t') ++q;
        if (*q == '\0' || *q == '\n' || *q == '\r') break;
        char* end = nullptr;
        const long idx = std::strtol(q, &end, 10);
        if (end == q) fail("a face index is not a number");
        long v = idx > 0 ? idx - 1 : static_cast<long>(verts.size()) + idx;  // 1-based, or relative when negative
        if (idx == 0 || v < 0 || v >= static_cast<long>(verts.size())) {
          fail("face index " + std::to_string(idx) + " is outside the " + std::to_string(verts.size()) +
               " vertices defined so far");
        }
        poly.push_back(static_cast<int>(v));
        q = end;
        while (*q != '\0' && *q != ' ' && *q != '\t' && *q != '\n' && *q != '\r') ++q;  // skip /vt/vn
      }
      if (poly.size() < 3) fail("a face needs at least three vertices");
      for (std::size_t k = 1; k + 1 < poly.size(); ++k) tris.emplace_back(poly[0], poly[k], poly[k + 1]);
    }
  }
  std::fclose(f);
  if (tris.empty()) throw_error(path, ": no faces (f lines): not a surface");
  out.vertices.resize(static_cast<Eigen::Index>(verts.size()), 3);
  for (std::size_t i = 0; i < verts.size(); ++i) out.vertices.row(static_cast<Eigen::Index>(i)) = verts[i].transpose();
  out.tris.resize(static_cast<Eigen::Index>(tris.size()), 3);
  for (std::size_t i = 0; i < tris.size(); ++i) out.tris.row(static_cast<Eigen::Index>(i)) = tris[i].transpose();
  return out;
}

}  // namespace surgsim
