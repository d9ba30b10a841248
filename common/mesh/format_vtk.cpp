// VTK legacy: reading ASCII unstructured grids (tetrahedra only; 5.1 offsets/connectivity too), writing a
// tetrahedral mesh (with an optional node vector field) and a triangle surface.
#include "mesh/mesh.h"

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>
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
using internal::is_space;
using internal::printable;
using internal::read_whole_file;
using internal::write_whole_file;

TetMesh read_vtk(const std::string& path) {
  const std::string text = read_whole_file(path);
  if (core::text::trim(text).empty()) throw_error(path, ": empty mesh file");
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

}  // namespace surgsim::mesh
