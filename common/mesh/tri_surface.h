// A triangle surface with its own vertices (a visual surface read from .obj, the imaging pipeline's surfaces before
// they become a TetMesh's boundary, the mesher's sampled organ surfaces), and the checks and measures reported on it.
// Not SurfaceMesh (mesh.h): that one indexes the nodes of a TetMesh (its boundary) and owns no vertices.
#pragma once
#include <Eigen/Core>
#include <string>

namespace surgsim::mesh {

/// A triangle surface with its own vertices.
struct TriSurface {
  Eigen::MatrixX3d vertices;  // #V x 3, m
  Eigen::MatrixX3i tris;      // #F x 3, 0-based indices into vertices, counter-clockwise seen from outside
  std::string source;         // where it came from (a file, a pipeline step; "" when built in memory), for messages
};

/// Topology of a triangle surface.
struct TriSurfaceTopology {
  int vertices = 0;          // referenced vertices
  int edges = 0;             // undirected edges
  int boundary_edges = 0;    // edges used by one triangle (0 when closed)
  int nonmanifold_edges = 0; // edges used by more than two triangles, or twice in the same direction
  int nonmanifold_vertices = 0;  // vertices whose triangles form more than one fan
  int components = 0;        // connected components (through shared edges)
  int euler = 0;             // V - E + F
  bool closed_manifold() const { return boundary_edges == 0 && nonmanifold_edges == 0 && nonmanifold_vertices == 0; }
};
TriSurfaceTopology tri_surface_topology(const TriSurface& mesh);

/// Enclosed volume by the divergence theorem (m^3; positive when the triangles face outward) and area (m^2).
double tri_surface_volume(const TriSurface& mesh);
double tri_surface_area(const TriSurface& mesh);

/// Smallest triangle quality 4 sqrt(3) A / (l1^2 + l2^2 + l3^2) (1 equilateral, 0 degenerate).
double tri_surface_min_quality(const TriSurface& mesh);

/// Drops vertices no triangle uses and renumbers (order kept).
void compact_tri_surface(TriSurface& mesh);

/// Throws surgsim::core::Error "<what>: ..." unless the surface is closed, 2-manifold, consistently oriented and
/// connected, with finite coordinates and a positive enclosed volume.
void check_closed_surface(const TriSurface& mesh, const std::string& what);

}  // namespace surgsim::mesh
