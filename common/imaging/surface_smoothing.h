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

/// Vertex neighbours (sorted, unique) of each vertex.
std::vector<std::vector<int>> vertex_neighbours(const mesh::TriSurface& mesh);

}  // namespace surgsim::imaging
