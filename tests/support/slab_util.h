// A bottom-fixed slab with its precomputed tensors, a vertical single-point tool, and the detrended ripple of a force signal: shared by the liver
// contact tests (tests/haptic_node/organs/) and haptic_signal_bench (tests/bench/).
#pragma once
#include <algorithm>
#include <cmath>
#include <vector>

#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "compliance/precompute.h"
#include "mesh/box_mesh.h"
#include "tool/tool.h"

namespace surgsim::test {

/// An nx x ny x nz-cell box of size `size` (m) with its corner at the origin, every node of the bottom face (z = 0)
/// fixed, E = 3 kPa, nu = 0.45, and the "haptic" and "visual" tensors of its free surface nodes.
struct Slab {
  mesh::TetMesh mesh;
  mesh::SurfaceMesh surface;
  compliance::Tensors tensors;
  Slab(int nx, int ny, int nz, const Eigen::Vector3d& size) {
    mesh = mesh::make_box_mesh(nx, ny, nz, size);
    surface = mesh::boundary_surface(mesh);
    fem::FixedRegion region;
    region.has_plane = true;
    region.plane_point = {0, 0, 0.001};
    region.plane_normal = {0, 0, -1};
    const fem::FixedSet fixed = fem::fixed_set_from_region(mesh, region);
    const fem::ElasticModel model = fem::build_elastic_model(mesh, fem::Material{3000.0, 0.45}, fixed);
    const std::vector<int> contacts = compliance::contactable_nodes(mesh, fixed);
    tensors = compliance::precompute_tensors(model, contacts, compliance::standard_row_sets(mesh, contacts), {});
  }
};

/// A single-point tool whose tip is at `tip`, its shaft vertical (trocar 15 cm above).
inline tool::ToolGeometry vertical_tool(const Eigen::Vector3d& tip) {
  tool::ToolGeometry g{};
  g.direction = {0, 0, -1};
  g.trocar = tip + Eigen::Vector3d(0, 0, 0.15);
  g.tip = tip;
  g.jaw_normal = {1, 0, 0};
  g.jaw_tips = {tip, tip};
  g.point_count = 1;
  g.points[0] = tip;
  return g;
}

/// Peak-to-peak of y after removing its least-squares line in s, over the mean of y (0 when the mean is not > 0).
inline double detrended_ripple(const std::vector<double>& s, const std::vector<double>& y) {
  const double m = static_cast<double>(s.size());
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    sx += s[i];
    sy += y[i];
    sxx += s[i] * s[i];
    sxy += s[i] * y[i];
  }
  const double slope = (m * sxy - sx * sy) / (m * sxx - sx * sx), icpt = (sy - slope * sx) / m;
  double lo = HUGE_VAL, hi = -HUGE_VAL;
  for (std::size_t i = 0; i < s.size(); ++i) {
    const double r = y[i] - (icpt + slope * s[i]);
    lo = std::min(lo, r);
    hi = std::max(hi, r);
  }
  return sy / m > 0 ? (hi - lo) / (sy / m) : 0.0;
}

}  // namespace surgsim::test
