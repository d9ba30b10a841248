// Scenes: what to simulate and what each node builds (DESIGN.md section 6), loaded from YAML.
// Unknown keys and out-of-range values are errors naming the file, the line and the key.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "intestine_model.h"

namespace surgsim {

/// Where the organ's tetrahedral mesh comes from: a file, or the project's own generator.
struct MeshSource {
  std::string file;          // absolute path (resolved against the scene's folder); empty when generated
  std::string generate;      // "liver" | "plate" | "cylinder"; empty when `file` is set
  int target_nodes = 1500;   // approximate node count of a generated mesh, 100..100000
};

struct Material {
  double young_modulus = 3000.0;  // Pa, > 0
  double poisson_ratio = 0.45;    // [0, 0.5)
};

/// Fixed (clamped) nodes: the union of an index list, axis-aligned boxes and the negative side of a plane.
/// YAML: `fixed: {nodes: [..], box: {min, max}, boxes: [{min, max}, ..], plane: {point, normal}}`, all optional.
/// The single `box` key sets has_box/box_min/box_max AND is appended to `boxes`, so code that reads `boxes`
/// sees every box; fixes() covers both (a box present in both places is counted once, harmlessly).
struct FixedRegion {
  std::vector<int> nodes;                           // 0-based node indices in file order
  bool has_box = false;
  Eigen::Vector3d box_min = Eigen::Vector3d::Zero();  // m
  Eigen::Vector3d box_max = Eigen::Vector3d::Zero();  // m
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> boxes;  // (min, max) per box, m; min < max
  bool has_plane = false;
  Eigen::Vector3d plane_point = Eigen::Vector3d::Zero();   // m
  Eigen::Vector3d plane_normal = Eigen::Vector3d::UnitZ(); // unit; nodes with (x - point) . normal >= 0 are fixed

  /// True if node `index` at rest position `x` (m) is fixed: listed, inside a box (bounds inclusive) or on
  /// the fixed side of the plane.
  bool fixes(int index, const Eigen::Vector3d& x) const;
  /// True if nothing at all is fixed by this region.
  bool empty() const { return nodes.empty() && !has_box && boxes.empty() && !has_plane; }
};

/// Quasi non-linear law (paper section 3.4): curve files and polynomial degree. Empty files: linear only.
struct NonlinearSpec {
  std::string displacement_curve;  // absolute path, CSV x,d_r (m) or empty
  std::string force_curve;         // absolute path, CSV x,f (m, N) or empty
  int degree = 6;                  // 4..10
  bool enabled() const { return !displacement_curve.empty() || !force_curve.empty(); }
};

/// Laparoscopic tool through a trocar (5 DOF: pitch, yaw, insertion, roll, jaw).
struct ToolSpec {
  Eigen::Vector3d trocar = Eigen::Vector3d(0, 0, 0.2);   // m, fulcrum in world coordinates
  Eigen::Vector3d axis = Eigen::Vector3d(0, 0, -1);      // unit shaft direction (into the body) at pitch = yaw = 0
  double shaft_length = 0.35;    // m
  double shaft_radius = 0.0025;  // m, for drawing
  int shaft_points = 4;          // contact points along the shaft, tip first, 1..32
  double shaft_spacing = 0.01;   // m between contact points
  double jaw_length = 0.015;     // m
  double force_limit = 8.0;      // N, device force clamp
  int contact_capacity = 20;     // simultaneous contact nodes, 1..64 (ContactFrame bound)
};

struct HapticSpec {
  double rate_hz = 300.0;  // 50..20000
};

struct Camera {
  Eigen::Vector3d eye = Eigen::Vector3d(0.25, -0.3, 0.25);  // m
  Eigen::Vector3d target = Eigen::Vector3d::Zero();         // m
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  double fov_deg = 35.0;                                    // vertical field of view, (1, 170)
};

struct VisualSpec {
  double rate_hz = 50.0;   // 1..1000
  int width = 640;         // 16..8192
  int height = 480;        // 16..8192
  Camera camera;
  int png_every = 5;       // write every n-th rendered frame as PNG; 0 = no PNG
  bool vtk = false;        // write the deformed mesh as VTK with each PNG
  bool video = false;      // assemble an MP4 with ffmpeg at exit when available
  std::string surface;     // absolute path of a finer visual surface embedded in the mesh; empty = boundary
  double target_fps = 0;   // Hz, target of the intestine's frame-rate controller (paper eq. 15), 1..1000; 0 = rate_hz
};

/// The intestine's body (model "intestine"; Raghupathi et al. 2004, DESIGN.md 4.3), YAML `intestine: {...}`.
/// Every key is optional and defaults to intestine::IntestineParams (the paper's 4 m intestine on 4 x 100 masses):
///   rest shape: length, cylinder_radius, folds, angular_span, fold_shape, axis_origin, axis_direction, columns, rows
///     (rows x columns <= 2048, the BodyState bound), intestine_radius, mesentery_thickness;
///   masses and springs: intestine_node_mass, mesentery_node_mass, structural_stiffness, shear_stiffness,
///     bending_stiffness, spring_damping, drag, gravity, integrator (implicit_euler | symplectic_euler);
///   probe (a sphere at the tool tip): probe_radius, probe_stiffness; its force is clamped to tool.force_limit;
///   collisions: self_collisions, random_pairs (the paper's n), random_mesentery_pairs, seed, response_iterations,
///     contact_capacity.
struct IntestineSpec {
  intestine::IntestineParams params;  // ready for IntestineModel: probe_force_limit = tool.force_limit
  double probe_radius = 0.01;         // m
};

struct Scene {
  std::string name;        // e.g. "liver"
  std::string file;        // absolute path of the YAML it came from
  std::string dir;         // folder of `file`, for resolving relative paths
  std::string model = "liver";  // "liver" (precomputed FEM) | "intestine" (mass-spring)
  MeshSource mesh;
  Material material;
  FixedRegion fixed;
  NonlinearSpec nonlinear;
  ToolSpec tool;
  HapticSpec haptic;
  VisualSpec visual;
  IntestineSpec intestine;  // read for model "intestine" only
  std::string trajectory;  // absolute path of the default trajectory, may be empty

  /// Hash of everything both nodes must agree on: model, mesh source (file NAME, not path or content; or
  /// generator + target_nodes), material, fixed set, non-linear law (curve file names + degree), tool spec and
  /// haptic rate, and for model "intestine" every intestine parameter. Name, visual settings and trajectory do not
  /// enter it. Stable across hosts and runs.
  std::uint64_t hash() const;
};

/// Loads and validates a scene. Throws surgsim::Error "FILE:LINE: key 'a.b': <what is wrong> (<fix>)".
/// Every key is optional except `name` and `mesh` (`mesh` is optional for model "intestine"); unknown keys, wrong
/// types, out-of-range values and referenced files (mesh, curves, surface, trajectory) that do not exist are
/// errors. Relative paths are resolved against the scene file's folder; axes and normals are normalized.
Scene load_scene(const std::string& path);

/// Directory with shipped data (config/) for programs run from the build or source tree:
/// $SURGSIM_CONFIG_DIR if set, else the source tree's config/ compiled in.
std::string config_dir();

/// Resolves a scene argument: an existing path, or a shipped scene name ("liver" -> config/liver.yaml).
/// Throws surgsim::Error listing the shipped scenes when neither exists.
std::string resolve_scene_path(const std::string& name_or_path);

}  // namespace surgsim
