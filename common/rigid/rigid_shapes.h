// Generators of rigid organs' surfaces (an abdominal wall dome, rib arcs, a spine segment, plane and box walls), in
// their own frame: each is counter-clockwise seen from its free side (outside; inside for the dome used as a cavity)
// and consistently oriented, closed unless said otherwise. `placed` moves one into the scene.
#pragma once
#include <Eigen/Core>

#include "mesh/placement.h"
#include "mesh/tri_surface.h"

namespace surgsim::rigid {

/// The surface in the scene's frame: every vertex through `placement` (triangles and source kept).
mesh::TriSurface placed(const mesh::TriSurface& surface, const mesh::Placement& placement);

/// An open square grid of size_x by size_y (m) centred on the origin in the plane z = 0, normal +z, `divisions`
/// quads along each side (2 divisions^2 triangles).
mesh::TriSurface plane_patch(double size_x, double size_y, int divisions);

/// A closed box centred on the origin, half extents (m) along x, y, z, each face `divisions` x `divisions` quads.
mesh::TriSurface box_surface(const Eigen::Vector3d& half_extents, int divisions);

/// A straight tube along z from -length/2 to length/2 (m) of `radius` (m): `segments` around, `rings` quads along,
/// closed by flat fans at both ends when `capped` (a rib bar, a spine segment), open at both ends otherwise.
mesh::TriSurface tube_surface(double radius, double length, int segments, int rings, bool capped);

/// The ellipsoid x^2/a^2 + y^2/b^2 + z^2/c^2 = 1, radii (a, b, c) (m): `u_segments` around z, `v_segments` rings
/// from the top pole (0, 0, c) down. z_min_fraction > -1 opens it below z = z_min_fraction c (a dome: the abdominal
/// wall, used with cavity = true); <= -1 closes it with the bottom pole. Normals point outward.
mesh::TriSurface ellipsoid_shell(const Eigen::Vector3d& radii, int u_segments, int v_segments, double z_min_fraction);

/// A ribcage segment: `count` ribs, each a capped tube of tube_radius bent on a circular arc of arc_radius about
/// the z axis, spanning arc_deg centred on +x, the ribs stacked along z every `spacing` and centred on z = 0.
struct RibsSpec {
  int count = 5;
  double arc_radius = 0.12;    // m, from the axis to the rib's centre line
  double tube_radius = 0.006;  // m, the rib's cross-section
  double arc_deg = 120;        // degrees, (0, 360)
  double spacing = 0.03;       // m between ribs' centre lines
  int segments = 16;           // around each rib
  int arc_segments = 48;       // along each rib
};
mesh::TriSurface ribs(const RibsSpec& spec);

}  // namespace surgsim::rigid
