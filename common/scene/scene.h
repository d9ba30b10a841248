// Scenes: what to simulate and what each node builds (docs/DESIGN.md, section 'Scenes'), loaded from YAML.
// Unknown keys and out-of-range values are errors naming the file, the line and the key.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "intestine/intestine_spec.h"
#include "compliance/corotation.h"
#include "fem/material.h"
#include "nonlinear/nonlinear_law.h"
#include "mesh/mesh_source.h"
#include "tool/tool.h"

namespace surgsim::scene {

struct HapticSpec {
  double rate_hz = 300.0;  // 50..20000
  // The force stage before the device (haptic_node/force_stage.h): a contact damper (the virtual coupling) and a
  // passivity observer / controller (Hannaford & Ryu 2002) on the force sent.
  bool passivity = true;               // the passivity controller acts (the observer always runs)
  double coupling_damping = 3.0;       // N s/m along the contact force, 0..1000 (0: no coupling damper)
  double passivity_max_damping = 30.0; // N s/m, cap of the controller's variable damping, (0, 1000]
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
  double stream_fps = 0;   // Hz, frames JPEG-encoded onto surgsim/frame for the web view; 0 = off, 0..120
  int stream_quality = 75; // JPEG quality of the streamed frames, 1..100 (not in the scene hash: no physics)
};

/// The liver's run-time model, YAML
/// `liver: {deformation: linear | corotational | multirate, curves: cylinder | organ}`.
struct LiverOptions {
  compliance::LiverDeformation deformation =
      compliance::LiverDeformation::kLinear;  // corotational: warped compliance (compliance/corotation.h);
                                              // multirate: neo-Hookean tracker (nonlinear/multirate.h)
  bool organ_curves = false;  // curves: organ: P and Q fitted on the organ's own Newton indentations (cached)
  bool defaults() const { return deformation == compliance::LiverDeformation::kLinear && !organ_curves; }
};

struct Scene {
  std::string name;        // e.g. "liver"
  std::string file;        // absolute path of the YAML it came from
  std::string dir;         // folder of `file`, for resolving relative paths
  std::string model = "liver";  // "liver" (precomputed FEM) | "intestine" (mass-spring)
  mesh::MeshSource mesh;
  fem::Material material;
  fem::FixedRegion fixed;
  nonlinear::NonlinearSpec nonlinear;
  LiverOptions liver;       // read for model "liver" only
  /// The instruments: 1..kMaxInstruments, from the `tools:` list or the single `tool:` key (one
  /// instrument named "tool"). Never empty. Instrument i is ToolCommand/ForceFeedback instrument i.
  std::vector<tool::ToolSpec> tools = {tool::ToolSpec{}};
  HapticSpec haptic;
  VisualSpec visual;
  intestine::IntestineSpec intestine;  // read for model "intestine" only
  std::string trajectory;  // absolute path of the default trajectory, may be empty

  /// Hash of everything both nodes must agree on: model, mesh source (file NAME, not path or content; or
  /// generator + target_nodes), material, fixed set, non-linear law (curve file names + degree), tool spec and
  /// haptic rate, and for model "intestine" every intestine parameter. Name, visual settings and trajectory do not
  /// enter it. Stable across hosts and runs.
  std::uint64_t hash() const;
};

/// Loads and validates a scene. Throws surgsim::core::Error "FILE:LINE: key 'a.b': <what is wrong> (<fix>)".
/// Every key is optional except `name` and `mesh` (`mesh` is optional for model "intestine"); unknown keys, wrong
/// types, out-of-range values and referenced files (mesh, curves, surface, trajectory) that do not exist are
/// errors. Relative paths are resolved against the scene file's folder; axes and normals are normalized.
Scene load_scene(const std::string& path);

/// Directory with shipped data (config/) for programs run from the build or source tree:
/// $SURGSIM_CONFIG_DIR if set, else the source tree's config/ compiled in.
std::string config_dir();

/// Resolves a scene argument: an existing path, or a shipped scene name ("liver" -> config/liver.yaml).
/// Throws surgsim::core::Error listing the shipped scenes when neither exists.
std::string resolve_scene_path(const std::string& name_or_path);

}  // namespace surgsim::scene
