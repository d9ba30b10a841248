// Wavefront .obj: reading a triangle surface (v and f lines; polygons fanned into triangles).
#include "mesh/mesh.h"

#include <Eigen/Core>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "core/error.h"
#include "mesh/tri_surface.h"

using namespace surgsim::core;

namespace surgsim::mesh {

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

}  // namespace surgsim::mesh
