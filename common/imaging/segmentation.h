// From a segmented volume to a simulation-ready organ (Cotin et al. 1998, section 2). Stages:
//  1. select: the organ's label, a 3x3x3 majority filter against segmentation noise, the largest piece kept and
//     cavities filled (volume.h);
//  2. marching cubes: the voxel boundary's triangulation (marching_cubes.h), the reference triangle count;
//  3. smooth: Taubin lambda|mu smoothing, every vertex kept within max_distance of the voxel boundary
//     (surface_smoothing.h);
//  4. reduce: quadric + curvature edge collapse under the same bound, error-driven (the smooth, light surface),
//     then on to the surface vertex count the node budget calls for, each followed by flips and tangential
//     relaxation for the triangles' shape (surface_decimation.h) and by an offset along the normals that gives
//     back the volume stages 1-4 cut off, so that each encloses the organ's labelled voxels' volume
//     (restore_volume in surface_smoothing.h, same bound);
//  5. tetrahedralize: Gmsh's 3D Delaunay inside that surface, kept as the mesh boundary, at the requested node
//     count (mesh_closed_surface in the mesher).
// Stages 1-4 are this folder's own code (VTK is not available and CGAL is not installed; surface_decimation.h
// says why Gmsh's surface remeshing was not used); Gmsh, the project's mesher already, does stage 5.
// Init-time code: allocates and throws surgsim::core::Error with the file named.
#pragma once
#include <cstdint>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "mesh/mesh.h"
#include "mesh/tri_surface.h"
#include "mesher/organ_mesher.h"
#include "imaging/surface_decimation.h"
#include "imaging/surface_smoothing.h"
#include "imaging/volume.h"

namespace surgsim::imaging {

struct SegmentOptions {
  std::optional<std::int32_t> label;  // organ label; empty: the only non-zero label
  int target_nodes = 1500;            // tetrahedral mesh nodes, kMinOrganNodes..kMaxOrganNodes (about +-20 %)
  double max_distance = 1.0;          // voxels (of the smallest spacing): smoothing and reduction stay this close to
                                      // the voxel boundary; (0, 4]
  double surface_error = 0.25;        // voxels: the reduced surface stops where the next collapse would move it
                                      // more than this (quadric + curvature estimate); (0, max_distance]
  int smoothing_iterations = 30;      // Taubin lambda|mu pairs, 0..1000
  int denoise = 1;                    // majority_filter passes before the clean-up, 0..10 (0: voxels as given)
  bool clean = true;                  // keep the largest component and fill cavities (clean_mask)
};

/// Throws surgsim::core::Error with a one-line reason when an option is out of range.
void check_segment_options(const SegmentOptions& options);

/// Wall time of one stage.
struct StageTime {
  std::string name;
  double seconds = 0.0;
};

struct SegmentReport {
  std::int32_t label = 0;
  std::int64_t voxels = 0;               // in the volume
  std::int64_t organ_voxels = 0;         // of the selected label, after clean-up
  std::int64_t labelled_voxels = 0;      // of the selected label, after clean-up but before the majority filter
  std::int64_t denoised_voxels = 0;      // changed by the majority filter
  MaskCleanup cleanup;
  int genus = 0;                         // handles of the marching-cubes surface (0: sphere-like)
  int mc_vertices = 0, mc_triangles = 0;  // plain marching cubes
  SmoothingReport smoothing;
  DecimationReport surface;              // error-driven reduction: the smooth, light surface
  DecimationReport boundary;             // further reduction to the node budget's surface vertex count
  VolumeRestoreReport surface_restore;   // the surface's volume brought back to labelled_volume
  VolumeRestoreReport boundary_restore;  // the mesh boundary's (the surface's own when it needed no reduction)
  int boundary_target = 0;               // that vertex count (closed_surface_nodes)
  mesher::OrganMeshReport mesh;          // tetrahedralization
  double voxel_volume = 0.0;             // m^3, organ voxels x voxel volume
  double labelled_volume = 0.0;          // m^3, labelled voxels x voxel volume: what the surfaces enclose
  double mc_volume = 0.0;                // m^3, enclosed by each surface / the tets
  double surface_volume = 0.0;
  double mesh_volume = 0.0;
  double voxel_unit = 0.0;               // m, the "voxel" of distances (smallest spacing)
  std::vector<StageTime> stages;         // select, marching cubes, smooth, reduce, tetrahedralize
};

/// Everything the pipeline made, in world coordinates (m).
struct Segmentation {
  mesh::TriSurface marching_cubes;  // plain marching cubes of the cleaned mask
  mesh::TriSurface surface;         // smoothed and reduced (error-driven): the smooth, light surface
  mesh::TetMesh mesh;               // the tetrahedral mesh (its boundary: `surface` reduced to the node budget)
  SegmentReport report;
  std::string source;      // the volume's file or folder
};

/// Runs the pipeline. `progress`, if given, gets a line per stage as it ends; `mesher_log`, if given, each meshing
/// attempt and Gmsh's log. Deterministic.
Segmentation segment_volume(const LabelVolume& volume, const SegmentOptions& options, std::ostream* progress = nullptr,
                            std::ostream* mesher_log = nullptr);

/// Files written by write_segmentation.
struct SegmentationFiles {
  std::string msh, vtk, surface_vtk, scene;
};

/// Writes PREFIX.msh (Gmsh v2.2), PREFIX.vtk (tets), PREFIX_surface.vtk (the smooth, light surface) and
/// PREFIX.yaml: a liver-type scene (liver.yaml's structure) whose mesh is `file: <PREFIX name>.msh`, whose fixed
/// region is the mesh's lowest 14 % (as the liver's underside), whose tool comes straight down onto the mesh's
/// highest point, whose camera frames the mesh, and which uses liver.yaml's non-linear curves (absolute paths into
/// config_dir()) when they exist. Throws surgsim::core::Error naming the file that cannot be written.
SegmentationFiles write_segmentation(const Segmentation& segmentation, const std::string& prefix);

/// The scene text write_segmentation writes (mesh file name as given).
std::string segmentation_scene_yaml(const mesh::TetMesh& mesh, const std::string& name, const std::string& mesh_file,
                                    const std::string& source);

}  // namespace surgsim::imaging
