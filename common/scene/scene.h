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
#include "mesh/placement.h"
#include "tool/tool.h"

namespace surgsim::scene {

struct HapticSpec {
  double rate_hz = 300.0;  // 50..20000
  // The force stage before the device (haptic_node/force_stage.h): a contact damper (the virtual coupling) and a
  // passivity observer / controller (Hannaford & Ryu 2002) on the force sent.
  bool passivity = true;               // the passivity controller acts (the observer always runs)
  double coupling_damping = 3.0;       // N s/m along the contact force, 0..1000 (0: no coupling damper)
  double passivity_max_damping = 30.0; // N s/m, cap of the controller's variable damping, (0, 1000]
  // ContactFrame and the organs' own topics (a mass-spring body's BodyState: its every position) are published at
  // most this often; 0 = every tick. ForceFeedback is every tick's regardless. The visual node draws the newest at
  // its own rate, so more than a few per frame is work for nothing on every node that reads them (not in the scene
  // hash: no physics).
  double publish_hz = 0;  // Hz, 0 or 1..rate_hz
};

/// The picture's camera. YAML `camera: {eye, target, up, fov_deg}`, or a laparoscope through a port:
/// `camera: {port, target, insertion, angle_deg, roll_deg, up, fov_deg}`, whose eye and target load_scene sets
/// (scope_camera(): target is then the point looked at, on the oblique view direction; the scope keys stay as given).
struct Camera {
  Eigen::Vector3d eye = Eigen::Vector3d(0.25, -0.3, 0.25);  // m
  Eigen::Vector3d target = Eigen::Vector3d::Zero();         // m, looked at (the scope form: the shaft aims at it)
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  double fov_deg = 35.0;                                    // vertical field of view, (1, 170)
  // The scope form (scope true): the shaft goes from `port` towards the target; its tip, `insertion` m in, is the eye.
  bool scope = false;
  Eigen::Vector3d port = Eigen::Vector3d::Zero();  // m, where the scope enters the abdominal wall
  double insertion = 0.03;  // m from the port to the tip along the shaft, (0, port-target distance)
  double angle_deg = 0.0;   // oblique view: the view direction turned this far from the shaft, [0, 75] (0 or 30 usual)
  double roll_deg = 0.0;    // the scope turned about its shaft: the oblique side, 0 = towards `up`
};

/// The eye and target of a scope camera from its port, target (the point the shaft aims at), insertion, angle and
/// roll (camera.scope true; otherwise `camera` as it is). Applied once, by load_scene. The eye is the tip; the view
/// direction is the shaft's turned by angle_deg towards `up` (rolled by roll_deg about the shaft); the target is moved
/// onto it at the same distance from the eye.
Camera scope_camera(const Camera& camera);

/// How the picture is drawn, YAML `visual.render: {markers, light, falloff, wet}` (not in the scene hash).
struct RenderSpec {
  enum class Light { kStudio, kScope };
  bool markers = false;  // the contact nodes drawn as markers
  /// kScope: one light at the scope's tip (the eye) with distance falloff; kStudio: a key and a fill light fixed in
  /// view space. Default: kScope for a scope camera (`camera.port`), kStudio for an eye/target camera.
  Light light = Light::kStudio;
  Eigen::Vector3d falloff = Eigen::Vector3d(0.3, 0.0, 60.0);  // scope light: 1 / (a + b d + c d^2), d in m
  double wet = 1.0;  // wet speculars (a sharp highlight over a broad one), 0 = matte, [0, 2]
};

struct VisualSpec {
  double rate_hz = 50.0;   // 1..1000
  int width = 640;         // 16..8192
  int height = 480;        // 16..8192
  Camera camera;
  RenderSpec render;
  int png_every = 5;       // write every n-th rendered frame as PNG; 0 = no PNG
  bool vtk = false;        // write the deformed mesh as VTK with each PNG
  bool video = false;      // assemble an MP4 with ffmpeg at exit when available
  std::string surface;     // absolute path of a finer visual surface embedded in the mesh; empty = boundary
  double target_fps = 0;   // Hz, target of the intestine's frame-rate controller (paper eq. 15), 1..1000; 0 = rate_hz
  double stream_fps = 0;   // Hz, frames JPEG-encoded onto surgsim/frame for the web view; 0 = off, 0..120
  int stream_quality = 75; // JPEG quality of the streamed frames, 1..100 (not in the scene hash: no physics)
  double min_render_scale = 1.0;  // dynamic resolution: the lowest scale frames may be drawn at when their work does
                                  // not fit the period (scaled back up to width x height), 0.25..1; 1 = always full
};

/// The liver's run-time model, YAML
/// `liver: {deformation: linear | corotational | multirate, curves: cylinder | organ}`.
struct LiverOptions {
  compliance::LiverDeformation deformation =
      compliance::LiverDeformation::kLinear;  // corotational: warped compliance (compliance/corotation.h);
                                              // multirate: neo-Hookean tracker (nonlinear/multirate.h)
  bool organ_curves = false;  // curves: organ: P and Q fitted on the organ's own Newton indentations (cached)
  double wall_reach = 0.08;   // m, wall_reach: the field's rigid organs hold the liver's free surface nodes this near
                              // them at rest (the motion an instrument may give the liver; run time only, not hashed)
  bool defaults() const { return deformation == compliance::LiverDeformation::kLinear && !organ_curves; }
};

/// A rigid organ (abdominal wall, ribs, spine): a static triangle surface an instrument's tip is held on by a proxy
/// (god-object) and a virtual coupling. YAML `rigid: {file: wall.obj | generate: plane | box | tube | dome | ribs, ...}`.
/// The generators' dimensions are in the organ's own frame (its placement puts them in the scene).
struct RigidSpec {
  std::string file;      // absolute path of a Wavefront .obj surface; empty when generated
  std::string generate;  // plane | box | tube | dome | ribs; empty when `file` is set
  Eigen::Vector3d size = Eigen::Vector3d(0.1, 0.1, 0.1);  // m: plane [x, y, -]; box full extents; tube [radius,
                                                           // length, -]; dome radii; ribs [arc radius, spacing, bar
                                                           // radius]
  int count = 5;               // ribs: the number of rib arcs, 1..24
  double arc_deg = 150;        // ribs: the angle each arc spans, (0, 360)
  double dome_open_z = 0;      // dome: the dome is cut at z = dome_open_z * radii.z (open below), [-1, 1)
  bool cavity = false;         // the free side is inside (the abdominal wall seen from the abdomen)
  double stiffness = 2000.0;   // N/m, the virtual coupling's spring (default: the 2 N/mm a desktop device renders)
  double damping = 15.0;       // N s/m, the coupling's damper on the gap's rate, 0..1000 (rigid/proxy.h: passive
                               // at 1 kHz for light to heavy devices with k = 2000 N/m)
};

/// One organ of a scene: its name, its model and that model's keys, and its placement. A one-organ scene written in
/// the single-organ form (top-level `model:`, `mesh:` ...) is one OrganSpec named after the scene, placed at the
/// origin.
struct OrganSpec {
  std::string name;             // unique in the scene; names the organ in stats, logs and errors
  std::string model = "liver";  // "liver" (precomputed FEM) | "intestine" (mass-spring) | "rigid" (static surface)
  int line = 1;                 // the scene file's line the organ starts on (for errors found after loading)
  std::string key;              // its key path in the scene ("" for the single-organ form, "organs[i]" in a list)
  mesh::Placement placement;    // the organ's frame in the scene's
  mesh::MeshSource mesh;        // model liver
  fem::Material material;
  fem::FixedRegion fixed;       // in the organ's own frame
  nonlinear::NonlinearSpec nonlinear;
  LiverOptions liver;                  // model liver
  intestine::IntestineSpec intestine;  // model intestine (its axis in the organ's frame)
  RigidSpec rigid;                     // model rigid
  /// Display colour (sRGB, [0, 1] each), YAML `colour` or `color`; not given: the visual node's default for its model
  /// and name (visual only: not in the scene hash).
  bool has_colour = false;
  Eigen::Vector3d colour = Eigen::Vector3d::Constant(0.8);
};

struct Scene {
  std::string name;        // e.g. "liver"
  std::string file;        // absolute path of the YAML it came from
  std::string dir;         // folder of `file`, for resolving relative paths
  std::string model = "liver";  // "liver" (precomputed FEM) | "intestine" (mass-spring) | "organs" (an `organs:`
                                // list: see organs)
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
  mesh::Placement placement;  // organ_scene(i) of a list: organ i's placement (identity in the single-organ form)
  RigidSpec rigid;            // organ_scene(i) of a rigid organ: its surface and coupling
  /// Every organ, in the order given (never empty). A single-organ scene has one, mirroring the top-level keys
  /// above (model, mesh, material, fixed, nonlinear, liver, intestine), named after the scene. A scene with an
  /// `organs:` list has model "organs" and leaves those top-level keys at their defaults: read organs[i], or
  /// organ_scene(i).
  std::vector<OrganSpec> organs;

  /// True for a scene written with an `organs:` list (any count), false for the single-organ form.
  bool organ_list() const { return model == "organs"; }
  /// A single-organ view of organ i: this scene with the top-level model keys set to organ i's (what the code that
  /// builds one organ reads). The name stays the scene's; the tools, haptic and visual settings are shared.
  Scene organ_scene(std::size_t i) const;

  /// Hash of everything both nodes must agree on: model, mesh source (file NAME, not path or content; or
  /// generator + target_nodes), material, fixed set, non-linear law (curve file names + degree), tool spec and
  /// haptic rate, and for model "intestine" every intestine parameter; for an `organs:` list, each organ's name,
  /// model, placement and keys (a rigid organ's surface file name or generator, and its coupling). Name, visual
  /// settings and trajectory do not enter it. Stable across hosts and runs; a single-organ scene keeps the hash it
  /// had before organ lists existed.
  std::uint64_t hash() const;
};

/// Organs a scene lists at most.
inline constexpr int kMaxOrgans = 8;

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
