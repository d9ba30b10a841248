// Helpers shared by surgsim-precompute and surgsim-solve: parsing of node lists, vectors and imposed displacements,
// mesh loading (file or generated organ), fixed regions, and a progress printer. Header-only; used by the mains only.
#pragma once
#include <Eigen/Core>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/text.h"
#include "fem/fixed_set.h"
#include "mesh/mesh.h"
#include "compliance/precompute.h"
#include "scene/scene.h"
#include "fem/static_solver.h"
#include "mesher/organ_mesher.h"

namespace surgsim::apps::cli {

inline std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  for (const std::string_view f : core::text::split(s, sep)) out.emplace_back(f);
  return out;
}

inline std::string trim(const std::string& s) { return std::string(core::text::trim(s)); }

/// A finite number, the whole string; throws surgsim::core::Error naming `what`.
inline double parse_number(const std::string& field, const std::string& what) {
  double v = 0;
  if (core::text::parse_double(field, v) == core::text::Number::kOk) return v;
  core::throw_error(what, ": '", field, "' is not a finite number");
}

/// A non-negative integer node index, the whole string.
inline int parse_index(const std::string& text, const std::string& what) {
  const std::string t = trim(text);
  if (t.empty() || t.find_first_not_of("0123456789") != std::string::npos || t.size() > 9)
    core::throw_error(what, ": '", text, "' is not a node index (0-based integer)");
  return std::stoi(t);
}

/// "i,j,k" -> node indices.
inline std::vector<int> parse_index_list(const std::string& text, const std::string& what) {
  std::vector<int> out;
  for (const auto& p : split(text, ',')) out.push_back(parse_index(p, what));
  return out;
}

/// "a,b,c,..." with exactly n numbers.
inline std::vector<double> parse_numbers(const std::string& text, std::size_t n, const std::string& what) {
  const auto parts = split(text, ',');
  if (parts.size() != n)
    core::throw_error(what, ": '", text, "' needs ", n, " comma-separated numbers, got ", parts.size());
  std::vector<double> v;
  for (const auto& p : parts) v.push_back(parse_number(p, what));
  return v;
}

/// "NODE:ux,uy,uz" (m); an empty component is left free, e.g. "12:,,-0.002" imposes only z.
inline fem::ImposedDisplacement parse_impose(const std::string& text) {
  const std::string what = "--impose '" + text + "'";
  const auto colon = text.find(':');
  if (colon == std::string::npos)
    core::throw_error(what, ": expected NODE:ux,uy,uz (metres; leave a component empty to leave it free)");
  fem::ImposedDisplacement im;
  im.node = parse_index(text.substr(0, colon), what);
  const auto comps = split(text.substr(colon + 1), ',');
  if (comps.size() != 3)
    core::throw_error(what, ": expected 3 components ux,uy,uz after the colon, got ", comps.size());
  im.components = 0;
  for (int c = 0; c < 3; ++c) {
    if (trim(comps[static_cast<std::size_t>(c)]).empty()) continue;
    im.value[c] = parse_number(comps[static_cast<std::size_t>(c)], what);
    im.components = static_cast<std::uint8_t>(im.components | (1u << c));
  }
  if (im.components == 0) core::throw_error(what, ": no component given");
  return im;
}

/// Fixed-region options as given on the command line.
struct FixedOptions {
  std::string nodes;               // "i,j,k"
  std::string plane;               // "px,py,pz,nx,ny,nz"
  std::vector<std::string> boxes;  // "x0,y0,z0,x1,y1,z1" each
  bool any() const { return !nodes.empty() || !plane.empty() || !boxes.empty(); }
};

inline fem::FixedRegion fixed_region(const FixedOptions& o) {
  fem::FixedRegion r;
  if (!o.nodes.empty()) r.nodes = parse_index_list(o.nodes, "--fixed");
  if (!o.plane.empty()) {
    const auto v = parse_numbers(o.plane, 6, "--fixed-plane");
    r.has_plane = true;
    r.plane_point = Eigen::Vector3d(v[0], v[1], v[2]);
    r.plane_normal = Eigen::Vector3d(v[3], v[4], v[5]);
    if (r.plane_normal.norm() == 0)
      core::throw_error("--fixed-plane: the normal (last three numbers) must not be zero");
  }
  for (const auto& b : o.boxes) {
    const auto v = parse_numbers(b, 6, "--fixed-box");
    const Eigen::Vector3d lo(v[0], v[1], v[2]), hi(v[3], v[4], v[5]);
    if (!(lo.array() <= hi.array()).all()) core::throw_error("--fixed-box '", b, "': min must not exceed max");
    r.boxes.emplace_back(lo, hi);
  }
  return r;
}

/// --region's help: one material region, repeatable, a later one over an earlier one.
inline const char* const kRegionHelp =
    "A region of the mesh with its own material, by tet centroid: NAME:E,NU:box:x0,y0,z0,x1,y1,z1 or "
    "NAME:E,NU:ellipsoid:cx,cy,cz,rx,ry,rz (Pa, m); repeatable, a later region over an earlier one; the other tets "
    "have --young and --poisson";

/// "NAME:E,NU:box:x0,y0,z0,x1,y1,z1" or "NAME:E,NU:ellipsoid:cx,cy,cz,rx,ry,rz" -> a material region.
inline fem::MaterialRegion parse_region(const std::string& text) {
  const std::string what = "--region '" + text + "'";
  const auto parts = split(text, ':');
  if (parts.size() != 4 || (parts[2] != "box" && parts[2] != "ellipsoid") || trim(parts[0]).empty())
    core::throw_error(what, ": expected NAME:E,NU:box:x0,y0,z0,x1,y1,z1 or NAME:E,NU:ellipsoid:cx,cy,cz,rx,ry,rz");
  fem::MaterialRegion r;
  r.name = trim(parts[0]);
  r.where = what;
  const auto material = parse_numbers(parts[1], 2, what);
  r.young_modulus = material[0];
  r.poisson_ratio = material[1];
  const auto v = parse_numbers(parts[3], 6, what);
  const Eigen::Vector3d a(v[0], v[1], v[2]), b(v[3], v[4], v[5]);
  if (parts[2] == "box") {
    if (!(a.array() < b.array()).all()) core::throw_error(what, ": the box's min must be below its max");
    r.boxes.emplace_back(a, b);
  } else {
    if (!(b.array() > 0).all()) core::throw_error(what, ": the ellipsoid's radii must be > 0");
    r.ellipsoids.push_back(fem::Ellipsoid{a, b});
  }
  return r;
}

/// Reads and validates a mesh file, or generates an organ (needs the mesher).
inline mesh::TetMesh load_mesh(const std::string& file, const std::string& generate, int nodes, std::ostream* log) {
  if (!file.empty()) {
    mesh::TetMesh m = mesh::read_mesh(file);
    mesh::validate_mesh(m);
    return m;
  }
  mesher::OrganSpec spec;
  spec.shape = generate;
  spec.target_nodes = nodes;
  return mesher::generate_organ(spec, log);
}

/// Prints precompute progress on stderr at most every `period` seconds, and the last one.
class ProgressPrinter {
 public:
  explicit ProgressPrinter(bool quiet, double period = 0.5) : quiet_(quiet), period_(period) {}
  void operator()(const compliance::PrecomputeProgress& p) {
    if (quiet_) return;
    const auto now = std::chrono::steady_clock::now();
    const bool last = p.columns_done == p.columns_total;
    if (!last && printed_ && std::chrono::duration<double>(now - last_).count() < period_) return;
    last_ = now;
    printed_ = true;
    if (p.columns_done == 0)
      std::fprintf(stderr, "precompute: set up in %.1f s, solving %d columns\n", p.elapsed_s, p.columns_total);
    else
      std::fprintf(stderr, "precompute: %5.1f %% (%d / %d columns), elapsed %.1f s, eta %.1f s\n", 100 * p.fraction,
                   p.columns_done, p.columns_total, p.elapsed_s, p.eta_s);
  }

 private:
  bool quiet_;
  double period_;
  bool printed_ = false;
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace surgsim::apps::cli
