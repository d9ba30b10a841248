// Shared by the imaging tests and imaging_bench: the project's own test volumes (the generated liver, voxelized)
// and the round-trip figures (distances to the original surface in voxels, triangle counts, volume error).
#pragma once
#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <map>
#include <utility>
#include <vector>

#include "mesh/mesh.h"
#include "mesher/organ_mesher.h"
#include "imaging/segmentation.h"
#include "imaging/surface_distance.h"
#include "mesh/tri_surface.h"
#include "imaging/volume.h"

namespace surgsim::test {

/// A tetrahedral mesh's boundary as a compact triangle surface (outward).
inline mesh::TriSurface boundary_tri_surface(const mesh::TetMesh& mesh) {
  const mesh::SurfaceMesh s = mesh::boundary_surface(mesh);
  mesh::TriSurface out;
  out.vertices = mesh.nodes;
  out.tris = s.tris;
  mesh::compact_tri_surface(out);
  return out;
}

inline double tets_volume(const mesh::TetMesh& mesh) {
  double v = 0.0;
  for (int t = 0; t < mesh.tets.rows(); ++t) v += mesh::tet_volume(mesh, t);
  return v;
}

/// The original organ: the generated liver (generate_organ) and its boundary.
struct ReferenceOrgan {
  mesh::TetMesh mesh;
  mesh::TriSurface surface;
  double volume = 0.0;  // m^3
};

inline ReferenceOrgan reference_liver(int nodes) {
  ReferenceOrgan r;
  r.mesh = mesher::generate_organ(mesher::OrganSpec{"liver", nodes});
  r.surface = boundary_tri_surface(r.mesh);
  r.volume = tets_volume(r.mesh);
  return r;
}

/// A test volume: the reference voxelized at `spacing` (m), label `label`, optionally with seeded noise
/// (boundary voxels flipped with probability `noise`, plus `speckles` stray voxels).
inline imaging::LabelVolume liver_volume(const ReferenceOrgan& reference, double spacing, double noise = 0.0,
                                         int speckles = 0, std::uint32_t seed = 1, std::int32_t label = 1) {
  imaging::LabelVolume v = imaging::voxelize(reference.surface.vertices, reference.surface.tris, spacing, 2, label);
  if (noise > 0.0 || speckles > 0) add_label_noise(v, noise, speckles, seed);
  return v;
}

/// Round-trip figures against the original surface; distances in voxels of `spacing`.
struct RoundTrip {
  double surface_hausdorff = 0.0, surface_mean = 0.0;  // light surface vs original, voxels
  double mesh_hausdorff = 0.0, mesh_mean = 0.0;        // tet mesh boundary vs original, voxels
  double mc_hausdorff = 0.0, mc_mean = 0.0;            // plain marching cubes vs original, voxels
  int mc_triangles = 0, surface_triangles = 0, mesh_triangles = 0;
  double mc_volume_error = 0.0, surface_volume_error = 0.0, mesh_volume_error = 0.0;  // relative, signed
};

inline RoundTrip round_trip(const ReferenceOrgan& reference, const imaging::Segmentation& s, double spacing) {
  RoundTrip r;
  const double step = 0.25 * spacing;  // sampling of the surfaces for the distances
  const imaging::SurfaceDistance ds = imaging::surface_distance(s.surface, reference.surface, step);
  const mesh::TriSurface boundary = boundary_tri_surface(s.mesh);
  const imaging::SurfaceDistance dm = imaging::surface_distance(boundary, reference.surface, step);
  const imaging::SurfaceDistance dc = imaging::surface_distance(s.marching_cubes, reference.surface, step);
  r.surface_hausdorff = ds.hausdorff / spacing;
  r.surface_mean = ds.mean / spacing;
  r.mesh_hausdorff = dm.hausdorff / spacing;
  r.mesh_mean = dm.mean / spacing;
  r.mc_hausdorff = dc.hausdorff / spacing;
  r.mc_mean = dc.mean / spacing;
  r.mc_triangles = static_cast<int>(s.marching_cubes.tris.rows());
  r.surface_triangles = static_cast<int>(s.surface.tris.rows());
  r.mesh_triangles = static_cast<int>(boundary.tris.rows());
  r.mc_volume_error = mesh::tri_surface_volume(s.marching_cubes) / reference.volume - 1.0;
  r.surface_volume_error = mesh::tri_surface_volume(s.surface) / reference.volume - 1.0;
  r.mesh_volume_error = tets_volume(s.mesh) / reference.volume - 1.0;
  return r;
}

}  // namespace surgsim::test
