// Adaptive reduction of a closed triangle surface by edge collapse: quadric error metrics (M. Garland and
// P. Heckbert, "Surface simplification using quadric error metrics", SIGGRAPH 1997) plus a curvature term, so that
// flat parts lose their triangles first and curved parts (the liver's rims and lobe tips) keep more.
//
// Why this and not Gmsh's remeshing of a discrete surface with a curvature-based size field: every collapse here
// is checked against the distance to the voxel boundary, which Gmsh's remesher knows nothing of; a remesher needs a
// parametrization of the surface, which for the liver's closed surface failed at some sizes and fell back to a
// minute of MeshAdapt (see organ_mesher.cpp); and this runs in about a second at 1.5 mm voxels, deterministically.
// (CGAL's Surface_mesh_simplification would do the collapses but is not installed, and would still need the
// distance bound added; VTK is not available.)
//
// Cost of collapsing an edge to a point v: e_Q + e_K, both squared distances (m^2):
//  - e_Q = v^T Q v / w: the area-weighted mean squared distance from v to the planes of the original triangles
//    merged into the two ends (Q their summed plane quadrics, w the summed areas);
//  - e_K = (L^2 kappa / 8)^2: the sag of a chord of length L on a curve of curvature kappa, with L the longest edge
//    the collapse creates and kappa the largest principal curvature estimated on the input around either end
//    (floored at min_curvature so that flat regions still grade their triangles).
// Collapses run cheapest first while sqrt(cost) <= max_error and the surface has more than target_vertices.
// A collapse is refused when it would break the surface (link condition: the result stays a closed 2-manifold of
// the same topology), turn a triangle by more than max_normal_turn_deg, create a triangle of quality below
// min_quality, or put the new vertex, or the centroid or an edge midpoint of a new triangle, farther than
// max_distance from the voxel boundary.
#pragma once
#include "mesh/tri_surface.h"
#include "imaging/voxel_boundary.h"

namespace surgsim::imaging {

struct DecimationOptions {
  int target_vertices = 0;          // stop at this many vertices; 0: no count target
  double max_error = 0.0;           // m, stop when the cheapest collapse's sqrt(cost) exceeds it; 0: no error bound
  double max_distance = 0.0;        // m, > 0: distance bound to the voxel boundary (needs a VoxelBoundaryDistance)
  double min_quality = 0.25;        // 4 sqrt(3) A / sum l^2 of any created triangle, in [0, 1)
  double max_normal_turn_deg = 45.0;  // largest turn of a triangle's normal in one collapse
  double min_curvature = 0.0;       // 1/m, curvature floor; 0: 4 / (bounding-box diagonal)
};

struct DecimationReport {
  int collapses = 0;
  long refused_topology = 0;        // candidate collapses refused by the link condition
  long refused_shape = 0;           // ... by the normal turn or triangle quality
  long refused_distance = 0;        // ... by the distance bound
  int vertices = 0;                 // at the end
  int triangles = 0;                // at the end
  double last_error = 0.0;          // m, sqrt(cost) of the last collapse done
};

/// Shape improvement after a reduction, under the same distance bound: edge flips between nearly coplanar
/// triangles that raise the worse triangle's quality, then tangential relaxation (each vertex moves half-way
/// towards the area-weighted centroid of its triangles, within its tangent plane, when that raises its worst
/// triangle's quality and keeps every bound). The tetrahedra Gmsh builds against a surface are only as good as its
/// triangles. Topology is kept except for the flips (genus and vertex count unchanged).
struct ImprovementOptions {
  int rounds = 3;                   // flip + relax rounds
  double max_distance = 0.0;        // m, as DecimationOptions::max_distance
  double max_flip_angle_deg = 20.0; // flip only across edges whose two triangles' normals differ by less
  double max_normal_turn_deg = 30.0;  // largest turn of a triangle's normal by a flip or a move
};

struct ImprovementReport {
  int flips = 0;
  int moves = 0;
  double min_quality_before = 0.0;  // worst triangle
  double min_quality_after = 0.0;
};

/// Improves the surface in place (grid frame, m). `boundary` may be null when max_distance is 0.
ImprovementReport improve_surface(mesh::TriSurface& mesh, const VoxelBoundaryDistance* boundary,
                                  const ImprovementOptions& options);

/// Reduces the surface in place (grid frame, m); vertices are renumbered (compacted, order kept). `boundary` may be
/// null when max_distance is 0. The input must be a closed 2-manifold (check_closed_surface). Deterministic.
/// Throws surgsim::core::Error for bad options.
DecimationReport decimate_surface(mesh::TriSurface& mesh, const VoxelBoundaryDistance* boundary,
                                  const DecimationOptions& options);

}  // namespace surgsim::imaging
