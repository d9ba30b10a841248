#include "imaging/segmentation.h"

#include <Eigen/LU>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <ostream>
#include <sstream>

#include "core/error.h"
#include "imaging/marching_cubes.h"
#include "scene/scene.h"
#include "imaging/voxel_boundary.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::scene;
using namespace surgsim::mesher;

namespace surgsim::imaging {
namespace {

// The fixed region of the written scene: nodes in the lowest kFixedFraction of the mesh's height (the liver scene
// fixes z <= -0.025 m of a liver spanning z -0.036 .. 0.043 m: its lowest 14 %).
constexpr double kFixedFraction = 0.14;
// The trocar stands this far above the mesh's highest point (liver scene: 0.2 m above a top at 0.042 m).
constexpr double kTrocarHeight = 0.16;

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Grid frame to world; reverses the triangles when the axes are left-handed so that they still face outward.
TriSurface to_world(const TriSurface& grid_mesh, const VoxelGrid& grid) {
  TriSurface out = grid_mesh;
  for (Eigen::Index v = 0; v < out.vertices.rows(); ++v)
    out.vertices.row(v) = grid.to_world(grid_mesh.vertices.row(v).transpose()).transpose();
  if (grid.axes.determinant() < 0.0) out.tris.col(1).swap(out.tris.col(2));
  return out;
}

double tets_volume(const TetMesh& mesh) {
  double v = 0.0;
  for (int t = 0; t < mesh.tets.rows(); ++t) v += tet_volume(mesh, t);
  return v;
}

// Numbers in YAML: short, round-trippable enough for metres.
std::string num(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", x);
  return buf;
}

// A YAML double-quoted scalar.
std::string quoted(const std::string& text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

std::string vec(const Eigen::Vector3d& v) { return "[" + num(v.x()) + ", " + num(v.y()) + ", " + num(v.z()) + "]"; }

}  // namespace

void check_segment_options(const SegmentOptions& o) {
  if (o.target_nodes < kMinOrganNodes || o.target_nodes > kMaxOrganNodes)
    throw_error("node count ", o.target_nodes, " out of range ", kMinOrganNodes, "..", kMaxOrganNodes);
  if (!(o.max_distance > 0.0 && o.max_distance <= 4.0))
    throw_error("maximum distance to the voxel boundary ", o.max_distance, " voxels out of range (0, 4]");
  if (!(o.surface_error > 0.0 && o.surface_error <= o.max_distance))
    throw_error("surface error ", o.surface_error, " voxels out of range (0, maximum distance = ", o.max_distance, "]");
  if (o.denoise < 0 || o.denoise > 10) throw_error("majority filter passes ", o.denoise, " out of range 0..10");
  if (o.smoothing_iterations < 0 || o.smoothing_iterations > 1000)
    throw_error("smoothing iterations ", o.smoothing_iterations, " out of range 0..1000");
}

Segmentation segment_volume(const LabelVolume& volume, const SegmentOptions& options, std::ostream* progress,
                            std::ostream* mesher_log) {
  check_segment_options(options);
  Segmentation out;
  out.source = volume.source;
  SegmentReport& report = out.report;
  const VoxelGrid& grid = volume.grid;
  report.voxel_unit = grid.voxel_unit();
  report.voxels = grid.voxel_count();
  const double unit = report.voxel_unit;
  auto stage_done = [&](const std::string& name, std::chrono::steady_clock::time_point t0, const std::string& what) {
    report.stages.push_back({name, seconds_since(t0)});
    if (progress != nullptr) *progress << name << ": " << what << " (" << report.stages.back().seconds << " s)" << std::endl;
  };

  // Select: the organ's voxels, cleaned to one solid piece.
  auto t0 = std::chrono::steady_clock::now();
  VoxelMask mask = select_label(volume, options.label);
  // The organ's labelled volume is counted before the majority filter: besides the noise, the filter takes the
  // staircase's convex corners (2.7 % of a clean 2 cm^3 ellipsoid at 1 mm voxels, 4 % of a tube 9 mm wide), and
  // the surfaces are restored to the labelled volume, not to the filter's.
  std::optional<std::int64_t> unfiltered_voxels;
  if (options.denoise > 0) {
    VoxelMask unfiltered = mask;
    if (options.clean) clean_mask(unfiltered);
    unfiltered_voxels = unfiltered.count();
    report.denoised_voxels = majority_filter(mask, options.denoise);
  }
  if (options.clean) report.cleanup = clean_mask(mask);
  if (mask.count() == 0)
    throw_error(volume.source, ": nothing of label ", mask.label, " is left after the majority filter (the organ is ",
                "thinner than two voxels: skip the filter, --denoise 0)");
  report.label = mask.label;
  report.organ_voxels = mask.count();
  report.voxel_volume = static_cast<double>(report.organ_voxels) * grid.spacing.prod();
  report.labelled_voxels = unfiltered_voxels.value_or(report.organ_voxels);
  report.labelled_volume = static_cast<double>(report.labelled_voxels) * grid.spacing.prod();
  {
    std::ostringstream what;
    what << "label " << report.label << ", " << report.organ_voxels << " of " << report.voxels << " voxels";
    if (options.denoise > 0)
      what << "; majority filter changed " << report.denoised_voxels << " voxels (" << report.labelled_voxels
           << " labelled before it)";
    if (options.clean)
      what << "; dropped " << report.cleanup.removed_voxels << " voxels in " << report.cleanup.components - 1
           << " stray pieces, filled " << report.cleanup.filled_voxels << " voxels in " << report.cleanup.cavities
           << " cavities";
    stage_done("select", t0, what.str());
  }

  // Marching cubes: the staircase surface's triangulation, the reference for the triangle counts.
  t0 = std::chrono::steady_clock::now();
  TriSurface grid_surface = marching_cubes(mask);
  check_closed_surface(grid_surface, volume.source + ": marching cubes");
  report.mc_vertices = static_cast<int>(grid_surface.vertices.rows());
  report.mc_triangles = static_cast<int>(grid_surface.tris.rows());
  report.genus = (2 - tri_surface_topology(grid_surface).euler) / 2;
  out.marching_cubes = to_world(grid_surface, grid);
  report.mc_volume = tri_surface_volume(grid_surface);
  stage_done("marching cubes", t0,
             std::to_string(report.mc_triangles) + " triangles, " + std::to_string(report.mc_vertices) +
                 " vertices, genus " + std::to_string(report.genus));

  // Smooth: Taubin lambda|mu, clamped to the voxel boundary.
  t0 = std::chrono::steady_clock::now();
  const VoxelBoundaryDistance boundary(mask);
  SmoothingOptions smoothing;
  smoothing.iterations = options.smoothing_iterations;
  smoothing.max_distance = options.max_distance * unit;
  if (options.smoothing_iterations > 0) report.smoothing = smooth_surface(grid_surface, boundary, smoothing);
  {
    std::ostringstream what;
    what << report.smoothing.steps << " steps, " << report.smoothing.clamped << " vertex moves clamped, farthest vertex "
         << report.smoothing.max_distance / unit << " voxels from the voxel boundary";
    stage_done("smooth", t0, what.str());
  }

  // Reduce: error-driven first (the smooth, light surface), then to the node budget's surface vertex count.
  t0 = std::chrono::steady_clock::now();
  DecimationOptions reduce;
  reduce.max_distance = options.max_distance * unit;
  reduce.max_error = options.surface_error * unit;
  report.surface = decimate_surface(grid_surface, &boundary, reduce);
  ImprovementOptions improve;
  improve.max_distance = options.max_distance * unit;
  improve_surface(grid_surface, &boundary, improve);
  // The majority filter, marching cubes, smoothing and the reduction each cut inside the labelled voxels a little:
  // the volume goes back to theirs (restore_volume, under the same distance bound), here and again after the
  // reduction to the node budget.
  VolumeRestoreOptions restore;
  restore.target_volume = report.labelled_volume;
  restore.max_distance = options.max_distance * unit;
  report.surface_restore = restore_volume(grid_surface, boundary, restore);
  check_closed_surface(grid_surface, volume.source + ": reduced surface");
  out.surface = to_world(grid_surface, grid);
  report.surface_volume = tri_surface_volume(grid_surface);
  report.boundary_target = closed_surface_nodes(report.surface_volume, tri_surface_area(grid_surface), options.target_nodes);
  TriSurface mesh_surface = grid_surface;
  if (report.boundary_target > 0 && mesh_surface.vertices.rows() > report.boundary_target) {
    DecimationOptions budget;
    budget.max_distance = options.max_distance * unit;
    budget.target_vertices = report.boundary_target;
    // Rounder triangles than the error-driven pass needs: Gmsh keeps them as the tets' faces, and tets against
    // long thin boundary triangles come out flat.
    budget.min_quality = 0.4;
    report.boundary = decimate_surface(mesh_surface, &boundary, budget);
    improve_surface(mesh_surface, &boundary, improve);
    report.boundary_restore = restore_volume(mesh_surface, boundary, restore);
    check_closed_surface(mesh_surface, volume.source + ": mesh boundary");
  } else {
    report.boundary.vertices = static_cast<int>(mesh_surface.vertices.rows());
    report.boundary.triangles = static_cast<int>(mesh_surface.tris.rows());
    report.boundary_restore = report.surface_restore;
  }
  {
    std::ostringstream what;
    what << "surface " << report.surface.triangles << " triangles (" << report.surface.vertices << " vertices, "
         << report.mc_triangles / std::max(1, report.surface.triangles) << "x fewer than marching cubes); mesh "
         << "boundary " << report.boundary.triangles << " triangles (" << report.boundary.vertices
         << " vertices, budget " << report.boundary_target
         << "); volume restored to the labelled voxels' by offsets of " << report.surface_restore.offset / unit
         << " (surface) and " << report.boundary_restore.offset / unit << " voxels (mesh boundary), "
         << report.surface_restore.held + report.boundary_restore.held << " vertices held back at the bound";
    stage_done("reduce", t0, what.str());
  }

  // Tetrahedralize inside the kept boundary.
  t0 = std::chrono::steady_clock::now();
  if (mesh_surface.vertices.rows() >= options.target_nodes)
    throw_error(volume.source, ": the surface cannot be reduced below ", mesh_surface.vertices.rows(),
                " vertices within ", options.max_distance, " voxels of the voxel boundary, too many for ",
                options.target_nodes, " nodes: ask for more nodes or allow a larger maximum distance");
  const TriSurface world_boundary = to_world(mesh_surface, grid);
  try {
    out.mesh = mesh_closed_surface(world_boundary, options.target_nodes, mesher_log, &report.mesh);
  } catch (const Error& e) {
    throw_error(volume.source, ": tetrahedralization: ", e.what());
  }
  out.mesh.source = volume.source;
  report.mesh_volume = tets_volume(out.mesh);
  {
    std::ostringstream what;
    what << report.mesh.nodes << " nodes (wanted " << options.target_nodes << "), " << report.mesh.tets
         << " tets, worst quality " << report.mesh.min_quality << ", " << report.mesh.attempts << " meshing(s)";
    stage_done("tetrahedralize", t0, what.str());
  }
  return out;
}

std::string segmentation_scene_yaml(const TetMesh& mesh, const std::string& name, const std::string& mesh_file,
                                    const std::string& source) {
  const Eigen::Vector3d lo = mesh.nodes.colwise().minCoeff(), hi = mesh.nodes.colwise().maxCoeff();
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  const double height = hi.z() - lo.z();
  Eigen::Index top = 0;
  mesh.nodes.col(2).maxCoeff(&top);
  const Eigen::Vector3d top_point = mesh.nodes.row(top).transpose();
  // The liver scene's camera, scaled by the mesh's size against the liver's (bounding-box diagonal ~0.31 m).
  const double scale = (hi - lo).norm() / 0.31;
  const Eigen::Vector3d eye = centre + scale * Eigen::Vector3d(0.16, -0.24, 0.19);
  // The liver scene's quasi non-linear law, when its curve files are at hand (absolute paths: the scene is written
  // elsewhere than config/).
  const std::string curves = config_dir() + "/curves/";
  const bool nonlinear = std::filesystem::exists(curves + "liver_dr.csv") && std::filesystem::exists(curves + "liver_force.csv");
  std::ostringstream y;
  y << "# Organ rebuilt from a segmented volume by surgsim-segment (source: " << source << ").\n"
    << "# Same structure as config/liver.yaml; the fixed region, tool and camera are placed from the mesh's extent.\n"
    << "name: " << quoted(name) << "\n"
    << "model: liver\n"
    << "mesh:\n"
    << "  file: " << quoted(mesh_file) << "  # spans " << vec(lo) << " .. " << vec(hi) << " m\n"
    << "material:\n"
    << "  young_modulus: 3000.0     # Pa\n"
    << "  poisson_ratio: 0.45\n";
  if (nonlinear) {
    y << "nonlinear:\n"
      << "  # quasi non-linear law of config/liver.yaml (neo-Hookean cylinder of the same material)\n"
      << "  displacement_curve: " << quoted(curves + "liver_dr.csv") << "\n"
      << "  force_curve: " << quoted(curves + "liver_force.csv") << "\n"
      << "  degree: 6\n";
  }
  y << "fixed:\n"
    << "  # the underside: nodes in the lowest " << static_cast<int>(kFixedFraction * 100) << " % of the height\n"
    << "  plane: {point: " << vec(Eigen::Vector3d(centre.x(), centre.y(), lo.z() + kFixedFraction * height))
    << ", normal: [0, 0, -1]}\n"
    << "tool:\n"
    << "  trocar: " << vec(top_point + Eigen::Vector3d(0, 0, kTrocarHeight))
    << " # m; straight down onto the highest point of the surface\n"
    << "  axis: [0, 0, -1]\n"
    << "  shaft_length: 0.35\n"
    << "  shaft_radius: 0.0025\n"
    << "  shaft_points: 4\n"
    << "  shaft_spacing: 0.01\n"
    << "  jaw_length: 0.015\n"
    << "  force_limit: 8.0\n"
    << "  contact_capacity: 20\n"
    << "haptic:\n"
    << "  rate_hz: 300\n"
    << "visual:\n"
    << "  rate_hz: 50\n"
    << "  width: 640\n"
    << "  height: 480\n"
    << "  camera: {eye: " << vec(eye) << ", target: " << vec(centre) << ", up: [0, 0, 1], fov_deg: 35}\n"
    << "  png_every: 5\n"
    << "  vtk: false\n"
    << "  video: false\n";
  return y.str();
}

SegmentationFiles write_segmentation(const Segmentation& segmentation, const std::string& prefix) {
  namespace fs = std::filesystem;
  if (prefix.empty()) throw_error("output prefix is empty");
  SegmentationFiles files;
  files.msh = prefix + ".msh";
  files.vtk = prefix + ".vtk";
  files.surface_vtk = prefix + "_surface.vtk";
  files.scene = prefix + ".yaml";
  write_msh(files.msh, segmentation.mesh);
  write_vtk(files.vtk, segmentation.mesh);
  write_vtk_surface(files.surface_vtk, segmentation.surface.vertices, segmentation.surface.tris);
  const std::string name = fs::path(prefix).filename().string();
  const std::string text =
      segmentation_scene_yaml(segmentation.mesh, name, fs::path(files.msh).filename().string(), segmentation.source);
  std::FILE* f = std::fopen(files.scene.c_str(), "w");
  if (f == nullptr) throw_error(files.scene, ": cannot create the scene file (check that its folder exists and is writable)");
  const bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
  if (std::fclose(f) != 0 || !ok) throw_error(files.scene, ": write failed");
  return files;
}

}  // namespace surgsim::imaging
