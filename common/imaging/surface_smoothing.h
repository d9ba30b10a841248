// Removing marching cubes' staircase without leaving the voxels: Taubin's lambda|mu smoothing (G. Taubin, "A signal
// processing approach to fair surface design", SIGGRAPH 1995), a low-pass filter that does not shrink the surface
// the way plain Laplacian smoothing does, with every vertex clamped after each step to within `max_distance` of the
// voxel boundary (projected back onto that distance along the direction to its nearest boundary point).
#pragma once
#include "mesh/tri_surface.h"
#include "imaging/voxel_boundary.h"

namespace surgsim::imaging {

struct SmoothingOptions {
  int iterations = 30;         // lambda|mu pairs
  double lambda = 0.5;         // shrinking step, (0, 1)
  double mu = -0.53;           // inflating step, < -lambda (pass band 1/lambda + 1/mu ~ 0.11)
  double max_distance = 0.0;   // m, > 0: how far a vertex may be from the voxel boundary
};

struct SmoothingReport {
  int steps = 0;               // umbrella steps taken (2 x iterations)
  long clamped = 0;            // vertex moves cut back to max_distance, over all steps
  double max_distance = 0.0;   // m, largest vertex distance to the voxel boundary at the end (<= the option)
  double mean_move = 0.0;      // m, mean distance a vertex moved from where it started
};

/// Smooths the surface in place (grid frame, m; topology unchanged). Uniform umbrella weights, which also evens
/// out marching cubes' triangle shapes. Throws surgsim::core::Error for bad options.
SmoothingReport smooth_surface(mesh::TriSurface& mesh, const VoxelBoundaryDistance& boundary,
                               const SmoothingOptions& options);

/// Restoring the enclosed volume. Marching cubes of a binary mask cuts the voxels' corners (its vertices sit on
/// the voxel edges' midpoints), smoothing rounds what is left, and a reduction's chords cut inside every convex
/// part: each stage stays within a voxel of the voxel boundary, yet together they lose a few per cent of a small
/// organ's volume (marching cubes alone about 3.6 % of a 2 cm^3 ellipsoid at 1 mm voxels, 5 % of a tube 9 mm
/// wide). restore_volume moves every vertex by one offset along its vertex normal (the surface's parallel surface,
/// to first order) until the surface encloses `target_volume` again, and keeps the bound: a vertex whose move
/// would take a vertex, a triangle's centroid or an edge's midpoint that was within max_distance of the voxel
/// boundary out of it, or turn a triangle by more than max_normal_turn_deg, moves less (its offset halved, round
/// after round, the others taking over its share), and after the last round, not at all.
struct VolumeRestoreOptions {
  double target_volume = 0.0;         // m^3, > 0: the volume to enclose (the organ's voxels)
  double max_distance = 0.0;          // m, > 0: as SmoothingOptions::max_distance
  double max_normal_turn_deg = 30.0;  // largest turn of a triangle's normal, in (0, 90)
  int rounds = 8;                     // offset solves, each after holding back the vertices that broke a bound
};

struct VolumeRestoreReport {
  double volume_before = 0.0;  // m^3, enclosed before
  double volume_after = 0.0;   // m^3, enclosed after (target_volume unless vertices were held back at the bound)
  double offset = 0.0;         // m, the common offset along the vertex normals (+ outward)
  int held = 0;                // vertices that moved less than the offset
};

/// Restores the enclosed volume in place (grid frame, m; topology unchanged). The surface must be closed and
/// outward (check_closed_surface). Deterministic. Throws surgsim::core::Error for bad options.
VolumeRestoreReport restore_volume(mesh::TriSurface& mesh, const VoxelBoundaryDistance& boundary,
                                   const VolumeRestoreOptions& options);

/// Vertex neighbours (sorted, unique) of each vertex.
std::vector<std::vector<int>> vertex_neighbours(const mesh::TriSurface& mesh);

}  // namespace surgsim::imaging
