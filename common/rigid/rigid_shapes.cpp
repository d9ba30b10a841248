// The rigid organs' generators. Tubes (straight or bent) share one sweep of a circle along a centre line.
#include "rigid/rigid_shapes.h"

#include <cmath>
#include <vector>

#include "core/error.h"

namespace surgsim::rigid {

namespace {

constexpr double kPi = 3.14159265358979323846;

// Builds a TriSurface from vertex and triangle lists.
mesh::TriSurface assemble(const std::vector<Eigen::Vector3d>& vertices, const std::vector<Eigen::Vector3i>& tris,
                          const char* source) {
  mesh::TriSurface s;
  s.vertices.resize(static_cast<Eigen::Index>(vertices.size()), 3);
  for (std::size_t i = 0; i < vertices.size(); ++i)
    s.vertices.row(static_cast<Eigen::Index>(i)) = vertices[i].transpose();
  s.tris.resize(static_cast<Eigen::Index>(tris.size()), 3);
  for (std::size_t i = 0; i < tris.size(); ++i) s.tris.row(static_cast<Eigen::Index>(i)) = tris[i].transpose();
  s.source = source;
  return s;
}

void require(bool ok, const char* what, const char* fix) {
  if (!ok) core::throw_error(what, ": ", fix);
}

// Sweeps a circle of `radius` along the centre line `centres` with frames (u[i], w[i]) (unit, perpendicular to the
// line; u x w points along it), `segments` around, appending to vertices/tris: outward normals, flat end fans when
// capped.
void sweep_tube(const std::vector<Eigen::Vector3d>& centres, const std::vector<Eigen::Vector3d>& u,
                const std::vector<Eigen::Vector3d>& w, double radius, int segments, bool capped,
                std::vector<Eigen::Vector3d>& vertices, std::vector<Eigen::Vector3i>& tris) {
  const int first = static_cast<int>(vertices.size());
  const int rings = static_cast<int>(centres.size());
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const double a = 2 * kPi * j / segments;
      vertices.push_back(centres[i] + radius * (std::cos(a) * u[i] + std::sin(a) * w[i]));
    }
  auto at = [&](int i, int j) { return first + i * segments + (j % segments); };
  // Around: +w at the angle 0, along: u x w, so (around) x (along) = u points out.
  for (int i = 0; i + 1 < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      tris.emplace_back(at(i, j), at(i, j + 1), at(i + 1, j + 1));
      tris.emplace_back(at(i, j), at(i + 1, j + 1), at(i + 1, j));
    }
  if (!capped) return;
  const int start = static_cast<int>(vertices.size());
  vertices.push_back(centres.front());
  const int end = static_cast<int>(vertices.size());
  vertices.push_back(centres.back());
  for (int j = 0; j < segments; ++j) {
    tris.emplace_back(start, at(0, j + 1), at(0, j));                // faces back along the line
    tris.emplace_back(end, at(rings - 1, j), at(rings - 1, j + 1));  // faces forward
  }
}

}  // namespace

mesh::TriSurface placed(const mesh::TriSurface& surface, const mesh::Placement& placement) {
  mesh::TriSurface out = surface;
  for (Eigen::Index v = 0; v < out.vertices.rows(); ++v)
    out.vertices.row(v) = placement.to_world(surface.vertices.row(v).transpose()).transpose();
  return out;
}

mesh::TriSurface plane_patch(double size_x, double size_y, int divisions) {
  require(size_x > 0 && size_y > 0 && divisions >= 1, "plane_patch",
          "sizes must be positive (m) and divisions at least 1");
  std::vector<Eigen::Vector3d> v;
  std::vector<Eigen::Vector3i> t;
  const int n = divisions + 1;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i)
      v.emplace_back(size_x * (static_cast<double>(i) / divisions - 0.5),
                     size_y * (static_cast<double>(j) / divisions - 0.5), 0.0);
  for (int j = 0; j < divisions; ++j)
    for (int i = 0; i < divisions; ++i) {
      const int a = i + n * j, b = a + 1, c = a + 1 + n, d = a + n;  // x then y: x cross y = +z
      t.emplace_back(a, b, c);
      t.emplace_back(a, c, d);
    }
  return assemble(v, t, "rigid::plane_patch");
}

mesh::TriSurface box_surface(const Eigen::Vector3d& half_extents, int divisions) {
  require((half_extents.array() > 0).all() && divisions >= 1, "box_surface",
          "half extents must be positive (m) and divisions at least 1");
  const int n = divisions + 1;
  std::vector<int> index(static_cast<std::size_t>(n * n * n), -1);  // lattice point -> vertex
  std::vector<Eigen::Vector3d> v;
  std::vector<Eigen::Vector3i> t;
  auto vertex = [&](const Eigen::Vector3i& l) {
    int& id = index[static_cast<std::size_t>(l.x() + n * (l.y() + n * l.z()))];
    if (id < 0) {
      id = static_cast<int>(v.size());
      v.emplace_back(((2.0 * l.cast<double>().array() / divisions - 1.0) * half_extents.array()).matrix());
    }
    return id;
  };
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      // e_b x e_c = e_axis (cyclic axes): walk (b, c) on the + face and (c, b) on the - face, outward either way.
      const int b = side == 1 ? (axis + 1) % 3 : (axis + 2) % 3;
      const int c = side == 1 ? (axis + 2) % 3 : (axis + 1) % 3;
      for (int q = 0; q < divisions; ++q)
        for (int p = 0; p < divisions; ++p) {
          auto at = [&](int dp, int dq) {
            Eigen::Vector3i l;
            l[axis] = side * divisions;
            l[b] = p + dp;
            l[c] = q + dq;
            return vertex(l);
          };
          const int a00 = at(0, 0), a10 = at(1, 0), a11 = at(1, 1), a01 = at(0, 1);
          t.emplace_back(a00, a10, a11);
          t.emplace_back(a00, a11, a01);
        }
    }
  return assemble(v, t, "rigid::box_surface");
}

mesh::TriSurface tube_surface(double radius, double length, int segments, int rings, bool capped) {
  require(radius > 0 && length > 0 && segments >= 3 && rings >= 1, "tube_surface",
          "radius and length must be positive (m), segments at least 3 and rings at least 1");
  std::vector<Eigen::Vector3d> centres, u, w, v;
  std::vector<Eigen::Vector3i> t;
  for (int i = 0; i <= rings; ++i) {
    centres.emplace_back(0, 0, length * (static_cast<double>(i) / rings - 0.5));
    u.push_back(Eigen::Vector3d::UnitX());
    w.push_back(Eigen::Vector3d::UnitY());
  }
  sweep_tube(centres, u, w, radius, segments, capped, v, t);
  return assemble(v, t, "rigid::tube_surface");
}

mesh::TriSurface ellipsoid_shell(const Eigen::Vector3d& radii, int u_segments, int v_segments, double z_min_fraction) {
  require((radii.array() > 0).all() && u_segments >= 3 && v_segments >= 2 && z_min_fraction < 1, "ellipsoid_shell",
          "radii must be positive (m), u_segments at least 3, v_segments at least 2 and z_min_fraction below 1");
  const bool closed = z_min_fraction <= -1;
  const double theta_max = closed ? kPi : std::acos(z_min_fraction);
  std::vector<Eigen::Vector3d> v;
  std::vector<Eigen::Vector3i> t;
  auto point = [&](double theta, double phi) {
    return Eigen::Vector3d(radii.x() * std::sin(theta) * std::cos(phi), radii.y() * std::sin(theta) * std::sin(phi),
                           radii.z() * std::cos(theta));
  };
  v.push_back(point(0, 0));  // top pole
  const int ring_count = closed ? v_segments - 1 : v_segments;
  for (int i = 1; i <= ring_count; ++i)
    for (int j = 0; j < u_segments; ++j) v.push_back(point(theta_max * i / v_segments, 2 * kPi * j / u_segments));
  auto at = [&](int i, int j) { return 1 + (i - 1) * u_segments + (j % u_segments); };
  // theta (down) x phi (around) points out.
  for (int j = 0; j < u_segments; ++j) t.emplace_back(0, at(1, j), at(1, j + 1));
  for (int i = 1; i < ring_count; ++i)
    for (int j = 0; j < u_segments; ++j) {
      t.emplace_back(at(i, j), at(i + 1, j), at(i + 1, j + 1));
      t.emplace_back(at(i, j), at(i + 1, j + 1), at(i, j + 1));
    }
  if (closed) {
    const int pole = static_cast<int>(v.size());
    v.push_back(point(kPi, 0));
    for (int j = 0; j < u_segments; ++j) t.emplace_back(at(ring_count, j), pole, at(ring_count, j + 1));
  }
  return assemble(v, t, "rigid::ellipsoid_shell");
}

mesh::TriSurface ribs(const RibsSpec& spec) {
  require(spec.count >= 1 && spec.arc_radius > spec.tube_radius && spec.tube_radius > 0 && spec.arc_deg > 0 &&
              spec.arc_deg < 360 && spec.spacing > 2 * spec.tube_radius && spec.segments >= 3 && spec.arc_segments >= 1,
          "ribs",
          "count at least 1, 0 < tube_radius < arc_radius (m), arc_deg in (0, 360), spacing above the ribs' "
          "diameter (they must not touch), segments at least 3 and arc_segments at least 1");
  std::vector<Eigen::Vector3d> v;
  std::vector<Eigen::Vector3i> t;
  const double arc = spec.arc_deg * kPi / 180;
  for (int r = 0; r < spec.count; ++r) {
    const double z = spec.spacing * (r - 0.5 * (spec.count - 1));
    std::vector<Eigen::Vector3d> centres, u, w;
    for (int i = 0; i <= spec.arc_segments; ++i) {
      const double phi = arc * (static_cast<double>(i) / spec.arc_segments - 0.5);
      const Eigen::Vector3d radial(std::cos(phi), std::sin(phi), 0);
      centres.push_back(spec.arc_radius * radial + Eigen::Vector3d(0, 0, z));
      u.push_back(Eigen::Vector3d::UnitZ());  // z x radial = the arc's direction
      w.push_back(radial);
    }
    sweep_tube(centres, u, w, spec.tube_radius, spec.segments, true, v, t);
  }
  return assemble(v, t, "rigid::ribs");
}

}  // namespace surgsim::rigid
