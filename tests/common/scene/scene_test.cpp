#include "scene/scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/error.h"
#include "mesh/geometry.h"
#include "mesher/scene_mesh.h"
#include "tool/tool.h"
#include "tool/trajectory.h"
#include "support/error_test_util.h"
#include "support/test_files.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::tool;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::intestine;
using namespace surgsim::scene;
using namespace surgsim::mesher;

namespace surgsim {
namespace {

namespace fs = std::filesystem;

fs::path test_dir() { return test::fresh_test_dir("scene_test_"); }

std::string write(const fs::path& path, const std::string& text) { return test::write_file(path, text); }

// The message of the Error load_scene throws, or "" if it loaded.
std::string load_error(const std::string& path) {
  return test::error_of([&] { load_scene(path); });
}

std::string shipped_config_dir() {
  const char* env = std::getenv("SURGSIM_CONFIG_DIR");
  return env != nullptr && *env != '\0' ? std::string(env) : std::string(SURGSIM_TEST_CONFIG_DIR);
}

const char* const kMinimal = "name: mini\nmesh: {generate: liver}\n";

// ---------------------------------------------------------------------------------------------------------------
// Defaults and valid input

TEST(SceneLoad, MinimalSceneGetsHeaderDefaults) {
  const fs::path dir = test_dir();
  const std::string path = write(dir / "mini.yaml", kMinimal);
  const Scene s = load_scene(path);
  EXPECT_EQ(s.name, "mini");
  EXPECT_EQ(s.model, "liver");
  EXPECT_EQ(fs::path(s.file), fs::absolute(path).lexically_normal());
  EXPECT_TRUE(fs::path(s.file).is_absolute());
  EXPECT_EQ(fs::path(s.dir), fs::absolute(dir).lexically_normal());
  EXPECT_EQ(s.mesh.generate, "liver");
  EXPECT_TRUE(s.mesh.file.empty());

  const MeshSource mesh;
  const Material mat;
  const ToolSpec tool;
  const HapticSpec haptic;
  const VisualSpec visual;
  EXPECT_EQ(s.mesh.target_nodes, mesh.target_nodes);
  EXPECT_EQ(s.material.young_modulus, mat.young_modulus);
  EXPECT_EQ(s.material.poisson_ratio, mat.poisson_ratio);
  EXPECT_TRUE(s.fixed.empty());
  EXPECT_FALSE(s.nonlinear.enabled());
  EXPECT_EQ(s.nonlinear.degree, NonlinearSpec().degree);
  EXPECT_EQ(s.tools[0].trocar, tool.trocar);
  EXPECT_EQ(s.tools[0].axis, tool.axis);
  EXPECT_EQ(s.tools[0].shaft_length, tool.shaft_length);
  EXPECT_EQ(s.tools[0].shaft_radius, tool.shaft_radius);
  EXPECT_EQ(s.tools[0].shaft_points, tool.shaft_points);
  EXPECT_EQ(s.tools[0].shaft_spacing, tool.shaft_spacing);
  EXPECT_EQ(s.tools[0].jaw_length, tool.jaw_length);
  EXPECT_EQ(s.tools[0].force_limit, tool.force_limit);
  EXPECT_EQ(s.tools[0].contact_capacity, tool.contact_capacity);
  EXPECT_EQ(s.tools[0].contact_model, ContactModel::kPatch);  // the smooth patch contact by default
  EXPECT_EQ(s.tools[0].tip_radius, 0.0025);                   // m: a 5 mm instrument, whatever the mesh
  EXPECT_EQ(s.tools[0].friction, 0.0);                       // frictionless
  EXPECT_EQ(s.haptic.rate_hz, haptic.rate_hz);
  EXPECT_EQ(s.haptic.passivity, haptic.passivity);
  EXPECT_TRUE(s.haptic.passivity);  // the passivity controller is on unless a scene turns it off
  EXPECT_EQ(s.haptic.coupling_damping, haptic.coupling_damping);
  EXPECT_EQ(s.haptic.passivity_max_damping, haptic.passivity_max_damping);
  EXPECT_EQ(s.visual.rate_hz, visual.rate_hz);
  EXPECT_EQ(s.visual.width, visual.width);
  EXPECT_EQ(s.visual.height, visual.height);
  EXPECT_EQ(s.visual.camera.eye, visual.camera.eye);
  EXPECT_EQ(s.visual.camera.fov_deg, visual.camera.fov_deg);
  EXPECT_EQ(s.visual.png_every, visual.png_every);
  EXPECT_EQ(s.visual.vtk, visual.vtk);
  EXPECT_EQ(s.visual.video, visual.video);
  EXPECT_TRUE(s.visual.surface.empty());
  EXPECT_TRUE(s.trajectory.empty());
}

TEST(SceneLoad, FullSceneWithRelativePaths) {
  const fs::path dir = test_dir();
  write(dir / "meshes" / "organ.msh", "$MeshFormat\n");
  write(dir / "meshes" / "fine_surface.vtk", "# vtk\n");
  write(dir / "curves" / "d.csv", "0,0\n");
  write(dir / "curves" / "f.csv", "0,0\n");
  write(dir / "traj" / "poke.csv", "# surgsim-trajectory v1\nt,pitch,yaw,insertion,roll,jaw\n0,0,0,0,0,0\n");
  const std::string path = write(dir / "scenes" / "full.yaml", R"(
name: full
model: liver
mesh:
  file: ../meshes/organ.msh
material: {young_modulus: 4500, poisson_ratio: 0.4}
fixed:
  plane: {point: [0, 0, -0.025], normal: [0, 0, -2]}
  box: {min: [-1, -1, -1], max: [1, 1, -0.5]}
  boxes:
    - {min: [0, 0, 0], max: [0.1, 0.1, 0.1]}
  nodes: [0, 5, 7]
nonlinear:
  displacement_curve: ../curves/d.csv
  force_curve: ../curves/f.csv
  degree: 8
tool:
  trocar: [0.03, 0.0, 0.20]
  axis: [0, 3, -4]
  shaft_length: 0.3
  shaft_radius: 0.002
  shaft_points: 5
  shaft_spacing: 0.02
  jaw_length: 0.01
  force_limit: 5
  contact_capacity: 32
  contact_model: triangle
  tip_radius: 0.004
  friction: 0.25
haptic: {rate_hz: 1000, passivity: false, coupling_damping: 1.5, passivity_max_damping: 12, publish_hz: 120}
visual:
  rate_hz: 60
  width: 800
  height: 600
  camera: {eye: [1, 0, 0], target: [0, 0, 0], up: [0, 0, 5], fov_deg: 40}
  png_every: 0
  vtk: true
  video: yes
  surface: ../meshes/fine_surface.vtk
trajectory: ../traj/poke.csv
)");
  const Scene s = load_scene(path);
  const fs::path root = fs::absolute(dir).lexically_normal();
  EXPECT_EQ(fs::path(s.mesh.file), root / "meshes" / "organ.msh");
  EXPECT_TRUE(s.mesh.generate.empty());
  EXPECT_EQ(fs::path(s.nonlinear.displacement_curve), root / "curves" / "d.csv");
  EXPECT_EQ(fs::path(s.nonlinear.force_curve), root / "curves" / "f.csv");
  EXPECT_EQ(fs::path(s.visual.surface), root / "meshes" / "fine_surface.vtk");
  EXPECT_EQ(fs::path(s.trajectory), root / "traj" / "poke.csv");
  EXPECT_NO_THROW(Trajectory::load(s.trajectory));

  EXPECT_EQ(s.material.young_modulus, 4500.0);
  EXPECT_EQ(s.material.poisson_ratio, 0.4);
  EXPECT_TRUE(s.nonlinear.enabled());
  EXPECT_EQ(s.nonlinear.degree, 8);
  // Normals and axes come back normalized.
  EXPECT_NEAR((s.fixed.plane_normal - Eigen::Vector3d(0, 0, -1)).norm(), 0.0, 1e-15);
  EXPECT_NEAR((s.tools[0].axis - Eigen::Vector3d(0, 0.6, -0.8)).norm(), 0.0, 1e-15);
  EXPECT_NEAR((s.visual.camera.up - Eigen::Vector3d(0, 0, 1)).norm(), 0.0, 1e-15);
  EXPECT_EQ(s.tools[0].shaft_points, 5);
  EXPECT_EQ(s.tools[0].contact_capacity, 32);
  EXPECT_EQ(s.tools[0].contact_model, ContactModel::kTriangle);
  EXPECT_EQ(s.tools[0].tip_radius, 0.004);
  EXPECT_EQ(s.tools[0].friction, 0.25);
  EXPECT_EQ(s.haptic.rate_hz, 1000.0);
  EXPECT_FALSE(s.haptic.passivity);
  EXPECT_EQ(s.haptic.coupling_damping, 1.5);
  EXPECT_EQ(s.haptic.passivity_max_damping, 12.0);
  EXPECT_EQ(s.haptic.publish_hz, 120.0);
  EXPECT_EQ(s.visual.width, 800);
  EXPECT_EQ(s.visual.png_every, 0);
  EXPECT_TRUE(s.visual.vtk);
  EXPECT_TRUE(s.visual.video);
  EXPECT_EQ(s.fixed.nodes, (std::vector<int>{0, 5, 7}));
  // The single box is the first entry of boxes (one representation), the list's boxes follow.
  ASSERT_EQ(s.fixed.boxes.size(), 2u);
  EXPECT_EQ(s.fixed.boxes[0].second, Eigen::Vector3d(1, 1, -0.5));
  EXPECT_EQ(s.fixed.boxes[1].second, Eigen::Vector3d(0.1, 0.1, 0.1));
}

TEST(SceneLoad, AbsolutePathsAreAccepted) {
  const fs::path dir = test_dir();
  const std::string mesh = write(dir / "m" / "organ.vtk", "# vtk\n");
  const std::string path =
      write(dir / "s" / "abs.yaml", "name: abs\nmesh: {file: '" + fs::absolute(mesh).string() + "'}\n");
  EXPECT_EQ(fs::path(load_scene(path).mesh.file), fs::absolute(mesh).lexically_normal());
}

TEST(SceneLoad, IntestineNeedsNoMesh) {
  const fs::path dir = test_dir();
  const Scene s = load_scene(write(dir / "i.yaml", "name: gut\nmodel: intestine\n"));
  EXPECT_EQ(s.model, "intestine");
  EXPECT_TRUE(s.mesh.generate.empty());
  EXPECT_TRUE(s.mesh.file.empty());
  // Without an `intestine` section the body is the model's default, its probe clamped to the tool's force limit.
  const intestine::IntestineParams defaults;
  EXPECT_EQ(s.intestine.params.columns, defaults.columns);
  EXPECT_EQ(s.intestine.params.rows, defaults.rows);
  EXPECT_EQ(s.intestine.params.probe_force_limit, s.tools[0].force_limit);
  EXPECT_EQ(s.visual.target_fps, 0.0);  // = the visual rate
}

TEST(SceneLoad, IntestineKeysFillTheModelParameters) {
  const fs::path dir = test_dir();
  const Scene s = load_scene(write(dir / "i.yaml",
                                   "name: gut\nmodel: intestine\n"
                                   "intestine:\n"
                                   "  length: 3.0\n  cylinder_radius: 0.12\n  folds: 4\n  angular_span: 5.0\n"
                                   "  fold_shape: 0.5\n  mesentery_taper: 0.2\n  axis_origin: [0, 0, 0.1]\n"
                                   "  axis_direction: [0, 2, 0]\n"
                                   "  columns: 80\n  rows: 5\n  intestine_radius: 0.015\n  mesentery_thickness: 0\n"
                                   "  intestine_node_mass: 0.01\n  mesentery_node_mass: 0.003\n"
                                   "  structural_stiffness: 1000\n  shear_stiffness: 200\n  bending_stiffness: 20\n"
                                   "  spring_damping: 0.2\n  drag: 1.5\n  gravity: [0, 0, -5]\n"
                                   "  integrator: symplectic_euler\n  probe_radius: 0.008\n  probe_stiffness: 500\n"
                                   "  self_collisions: false\n  random_pairs: 20\n  random_mesentery_pairs: 5\n"
                                   "  seed: 7\n  response_iterations: 2\n  contact_capacity: 256\n"
                                   "  obstacle_stiffness: 1500\n  obstacle_capacity: 64\n"
                                   "tool: {force_limit: 5}\n"
                                   "visual: {rate_hz: 30, target_fps: 45}\n"));
  const intestine::IntestineParams& p = s.intestine.params;
  EXPECT_EQ(p.length, 3.0);
  EXPECT_EQ(p.cylinder_radius, 0.12);
  EXPECT_EQ(p.folds, 4);
  EXPECT_EQ(p.angular_span, 5.0);
  EXPECT_EQ(p.fold_shape, 0.5);
  EXPECT_EQ(p.mesentery_taper, 0.2);
  EXPECT_EQ(p.axis_origin, Eigen::Vector3d(0, 0, 0.1));
  EXPECT_EQ(p.axis_direction, Eigen::Vector3d(0, 1, 0));  // normalized
  EXPECT_EQ(p.columns, 80);
  EXPECT_EQ(p.rows, 5);
  EXPECT_EQ(p.intestine_radius, 0.015);
  EXPECT_EQ(p.mesentery_thickness, 0.0);
  EXPECT_EQ(p.intestine_node_mass, 0.01);
  EXPECT_EQ(p.mesentery_node_mass, 0.003);
  EXPECT_EQ(p.structural_stiffness, 1000.0);
  EXPECT_EQ(p.shear_stiffness, 200.0);
  EXPECT_EQ(p.bending_stiffness, 20.0);
  EXPECT_EQ(p.spring_damping, 0.2);
  EXPECT_EQ(p.drag, 1.5);
  EXPECT_EQ(p.gravity, Eigen::Vector3d(0, 0, -5));
  EXPECT_EQ(p.integrator, intestine::Integrator::kSymplecticEuler);
  EXPECT_EQ(s.intestine.probe_radius, 0.008);
  EXPECT_EQ(p.probe_stiffness, 500.0);
  EXPECT_EQ(p.probe_force_limit, 5.0);
  EXPECT_FALSE(p.self_collisions);
  EXPECT_EQ(p.detection.random_pairs, 20);
  EXPECT_EQ(p.detection.random_mesentery_pairs, 5);
  EXPECT_EQ(p.detection.seed, 7u);
  EXPECT_EQ(p.response.iterations, 2);
  EXPECT_EQ(p.contact_capacity, 256);
  EXPECT_EQ(p.obstacle_stiffness, 1500.0);
  EXPECT_EQ(p.obstacle_capacity, 64);
  EXPECT_EQ(s.visual.target_fps, 45.0);
  EXPECT_NO_THROW(intestine::IntestineModel model(p));  // what the scene says, the model accepts
}

// Several instruments: a `tools:` list, each with its own settings; the single `tool:` key is one
// instrument named "tool".
TEST(SceneTools, ListGivesEachInstrumentItsOwnSettings) {
  const fs::path dir = test_dir();
  const Scene s = load_scene(write(dir / "two.yaml", std::string(kMinimal) + R"(tools:
  - name: grasper
    trocar: [-0.05, 0.04, 0.18]
    axis: [0.3, -0.2, -1]
    force_limit: 8
    friction: 0.3
    contact_capacity: 32
    jaw_length: 0.015
  - name: probe_2
    trocar: [0.08, -0.02, 0.19]
    axis: [0, 0, -2]
    force_limit: 5
    contact_capacity: 24
    tip_radius: 0.003
)"));
  ASSERT_EQ(s.tools.size(), 2u);
  const ToolSpec defaults;
  const ToolSpec& g = s.tools[0];
  const ToolSpec& p = s.tools[1];
  EXPECT_EQ(g.name, "grasper");
  EXPECT_EQ(p.name, "probe_2");
  EXPECT_EQ(g.trocar, Eigen::Vector3d(-0.05, 0.04, 0.18));
  EXPECT_EQ(p.trocar, Eigen::Vector3d(0.08, -0.02, 0.19));
  EXPECT_NEAR((g.axis - Eigen::Vector3d(0.3, -0.2, -1).normalized()).norm(), 0.0, 1e-15);
  EXPECT_NEAR((p.axis - Eigen::Vector3d(0, 0, -1)).norm(), 0.0, 1e-15);
  EXPECT_EQ(g.force_limit, 8.0);
  EXPECT_EQ(p.force_limit, 5.0);
  EXPECT_EQ(g.friction, 0.3);
  EXPECT_EQ(p.friction, defaults.friction);
  EXPECT_EQ(g.contact_capacity, 32);
  EXPECT_EQ(p.contact_capacity, 24);
  EXPECT_EQ(g.jaw_length, 0.015);
  EXPECT_EQ(p.jaw_length, defaults.jaw_length);
  EXPECT_EQ(g.tip_radius, defaults.tip_radius);
  EXPECT_EQ(p.tip_radius, 0.003);
  EXPECT_EQ(g.contact_model, ContactModel::kPatch);
  EXPECT_EQ(p.contact_model, ContactModel::kPatch);
}

TEST(SceneTools, SingleToolKeyIsOneInstrumentNamedTool) {
  const fs::path dir = test_dir();
  const Scene none = load_scene(write(dir / "none.yaml", kMinimal));
  ASSERT_EQ(none.tools.size(), 1u);
  EXPECT_EQ(none.tools[0].name, "tool");
  const Scene one = load_scene(write(dir / "one.yaml", std::string(kMinimal) + "tool: {trocar: [0.01, 0.02, 0.3]}\n"));
  ASSERT_EQ(one.tools.size(), 1u);
  EXPECT_EQ(one.tools[0].name, "tool");
  EXPECT_EQ(one.tools[0].trocar, Eigen::Vector3d(0.01, 0.02, 0.3));
  // A one-entry list is one instrument with its own name.
  const Scene listed = load_scene(write(dir / "listed.yaml", std::string(kMinimal) + "tools: [{name: hook}]\n"));
  ASSERT_EQ(listed.tools.size(), 1u);
  EXPECT_EQ(listed.tools[0].name, "hook");
}

TEST(FixedRegion, FixesListedNodesBoxesAndPlaneSide) {
  FixedRegion f;
  EXPECT_TRUE(f.empty());
  EXPECT_FALSE(f.fixes(0, Eigen::Vector3d::Zero()));
  f.nodes = {3};
  f.boxes.push_back({Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 1, 1)});
  f.has_plane = true;
  f.plane_point = Eigen::Vector3d(0, 0, -1);
  f.plane_normal = Eigen::Vector3d(0, 0, -1);
  EXPECT_TRUE(f.fixes(3, Eigen::Vector3d(5, 5, 5)));      // listed
  EXPECT_TRUE(f.fixes(0, Eigen::Vector3d(1, 0.5, 0)));    // on a box face (inclusive)
  EXPECT_TRUE(f.fixes(0, Eigen::Vector3d(5, 5, -1)));     // on the plane
  EXPECT_TRUE(f.fixes(0, Eigen::Vector3d(5, 5, -2)));     // fixed side
  EXPECT_FALSE(f.fixes(0, Eigen::Vector3d(5, 5, -0.5)));  // free side, outside the box
  FixedRegion g;
  g.boxes.emplace_back(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1, 1, 1));  // a box alone
  EXPECT_FALSE(g.empty());
  EXPECT_TRUE(g.fixes(9, Eigen::Vector3d(0, 0, 0)));
  EXPECT_FALSE(g.fixes(9, Eigen::Vector3d(0, 0, 2)));
}

// ---------------------------------------------------------------------------------------------------------------
// Shipped scenes

TEST(ShippedScenes, AllThreeLoadAndMatchTheirGeometry) {
  const fs::path cfg = shipped_config_dir();
  const Scene liver = load_scene((cfg / "liver.yaml").string());
  EXPECT_EQ(liver.name, "liver");
  EXPECT_EQ(liver.mesh.generate, "liver");
  EXPECT_TRUE(liver.fixed.has_plane);
  EXPECT_TRUE(liver.fixed.fixes(0, Eigen::Vector3d(0, 0, -0.03)));
  EXPECT_FALSE(liver.fixed.fixes(0, Eigen::Vector3d(0, 0, 0.0)));
  EXPECT_EQ(liver.tools[0].trocar, Eigen::Vector3d(0.03, 0, 0.2));
  EXPECT_GE(liver.haptic.rate_hz, 300.0);

  const Scene plate = load_scene((cfg / "plate.yaml").string());
  EXPECT_EQ(plate.mesh.generate, "plate");
  ASSERT_EQ(plate.fixed.boxes.size(), 4u);
  // Corners (top and bottom faces) are fixed; edge midpoints and the centre are not.
  for (double x : {-0.1, 0.1}) {
    for (double y : {-0.1, 0.1}) {
      for (double z : {-0.005, 0.005}) EXPECT_TRUE(plate.fixed.fixes(-1, Eigen::Vector3d(x, y, z)));
    }
  }
  EXPECT_FALSE(plate.fixed.fixes(-1, Eigen::Vector3d(0, -0.1, 0)));
  EXPECT_FALSE(plate.fixed.fixes(-1, Eigen::Vector3d(0, 0, 0.005)));
  EXPECT_EQ(plate.tools[0].trocar, Eigen::Vector3d(0.04, 0.03, 0.15));

  const Scene cyl = load_scene((cfg / "cylinder.yaml").string());
  EXPECT_EQ(cyl.mesh.generate, "cylinder");
  EXPECT_EQ(cyl.material.young_modulus, 3000.0);
  EXPECT_EQ(cyl.material.poisson_ratio, 0.45);
  EXPECT_TRUE(cyl.nonlinear.enabled());  // the tissue curves of the quasi non-linear law
  EXPECT_TRUE(cyl.fixed.fixes(-1, Eigen::Vector3d(0.02, 0, 0)));
  EXPECT_FALSE(cyl.fixed.fixes(-1, Eigen::Vector3d(0.02, 0, 0.01)));

  // Each names a trajectory that loads.
  for (const Scene* s : {&liver, &plate, &cyl}) {
    SCOPED_TRACE(s->name);
    ASSERT_FALSE(s->trajectory.empty());
    EXPECT_GT(Trajectory::load(s->trajectory).duration(), 1.0);
  }
}

// The poses the shipped trajectories drive: the tip starts above the top surface and goes the stated depth in.
// The intestine scene: the paper's body, and a tool whose tip reaches the hanging folds (x [-0.19, 0.2],
// y [-0.12, 0.13], z [-0.15, 0.04] m once gravity has acted) in both shipped trajectories.
TEST(ShippedScenes, IntestineLoadsAndItsTrajectoriesReachTheFolds) {
  const Scene s = load_scene((fs::path(shipped_config_dir()) / "intestine.yaml").string());
  EXPECT_EQ(s.model, "intestine");
  EXPECT_TRUE(s.mesh.generate.empty() && s.mesh.file.empty());
  EXPECT_EQ(s.intestine.params.columns * s.intestine.params.rows, 400);
  EXPECT_EQ(s.intestine.params.length, 4.0);
  EXPECT_GE(s.haptic.rate_hz, 1000.0);
  EXPECT_GT(s.visual.target_fps, 0.0);
  EXPECT_NO_THROW(intestine::IntestineModel model(s.intestine.params));
  for (const char* name : {"intestine_push.csv", "intestine_lift.csv"}) {
    SCOPED_TRACE(name);
    const Trajectory traj = Trajectory::load((fs::path(shipped_config_dir()) / "trajectories" / name).string());
    const auto tip = [&](const Pose5& p) { return tool_geometry(s.tools[0], p).tip; };
    const Eigen::Vector3d first = tip(traj.samples().front().pose);
    EXPECT_GT(first.y(), 0.13 + s.intestine.params.intestine_radius);  // starts clear of the folds
    double deepest_y = 1e9;
    for (const auto& smp : traj.samples()) deepest_y = std::min(deepest_y, tip(smp.pose).y());
    EXPECT_LT(deepest_y, 0.06);  // well inside the folds
    EXPECT_EQ(traj.samples().front().pose.insertion, traj.samples().back().pose.insertion);
  }
}

TEST(ShippedScenes, TrajectoriesReachTheStatedDepth) {
  struct Case {
    const char* scene;
    double top_z;  // m, top surface under the trocar
    double depth;  // m, how far the tip goes below it
  };
  for (const Case& c : {Case{"liver", 0.04, 0.015}, Case{"plate", 0.005, 0.005}, Case{"cylinder", 0.10, 0.01}}) {
    SCOPED_TRACE(c.scene);
    const Scene s = load_scene(resolve_scene_path(c.scene));
    const Trajectory traj = Trajectory::load(s.trajectory);
    double deepest = 1e9;
    double prev = traj.samples().front().pose.insertion;
    for (const auto& smp : traj.samples()) {
      const double tip_z = s.tools[0].trocar.z() + smp.pose.insertion * s.tools[0].axis.z();
      deepest = std::min(deepest, tip_z);
      EXPECT_LT(std::abs(smp.pose.insertion - prev), 0.001) << "jump at t = " << smp.t;  // smooth: < 1 mm / sample
      prev = smp.pose.insertion;
    }
    const auto& first = traj.samples().front().pose;
    const auto& last = traj.samples().back().pose;
    EXPECT_GT(s.tools[0].trocar.z() - first.insertion, c.top_z + 0.01);  // starts clear of the surface
    EXPECT_EQ(first.insertion, last.insertion);                      // retracts to where it started
    EXPECT_NEAR(deepest, c.top_z - c.depth, 1e-9);
  }
}

// Two hands: config/liver_two_tools.yaml and its trajectory against the scene's own mesh (generated, from
// the test cache). Each tip is followed along its shaft: it goes below the rest surface when the shaft's ray from the
// trocar meets the boundary before the tip.
struct RayHit {
  bool found = false;
  double s = 0;  // m from the trocar
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
};

RayHit first_hit(const TetMesh& mesh, const SurfaceMesh& surface, const Eigen::Vector3d& from,
                 const Eigen::Vector3d& direction) {
  RayHit hit;
  const double reach = 1.0;  // m, far beyond the organ
  for (int f = 0; f < surface.tris.rows(); ++f) {
    double s = 0;
    Eigen::Vector3d bary;
    if (mesh::segment_triangle(from, from + reach * direction, mesh.nodes.row(surface.tris(f, 0)).transpose(),
                               mesh.nodes.row(surface.tris(f, 1)).transpose(),
                               mesh.nodes.row(surface.tris(f, 2)).transpose(), s, bary) &&
        (!hit.found || s * reach < hit.s)) {
      hit.found = true;
      hit.s = s * reach;
      hit.point = from + hit.s * direction;
    }
  }
  return hit;
}

TEST(ShippedTwoToolScene, GrasperHoldsTheFreeLobeWhileTheProbePressesNearby) {
  const Scene s = load_scene(resolve_scene_path("liver_two_tools"));
  ASSERT_EQ(s.tools.size(), 2u);
  const ToolSpec& grasper = s.tools[0];
  const ToolSpec& probe = s.tools[1];
  EXPECT_EQ(grasper.name, "grasper");
  EXPECT_EQ(probe.name, "probe");
  EXPECT_GT((grasper.trocar - probe.trocar).norm(), 0.08);  // two ports
  for (const ToolSpec& t : s.tools) {
    EXPECT_EQ(t.force_limit, 8.0);
    EXPECT_EQ(t.contact_capacity, 32);  // together the solve's 64 contact nodes
    EXPECT_EQ(t.contact_model, ContactModel::kPatch);
  }
  // The organ is the shipped liver's (same mesh, material, law, fixed set).
  const Scene liver = load_scene(resolve_scene_path("liver"));
  EXPECT_EQ(s.mesh.generate, liver.mesh.generate);
  EXPECT_EQ(s.mesh.target_nodes, liver.mesh.target_nodes);
  EXPECT_EQ(s.material.young_modulus, liver.material.young_modulus);
  EXPECT_EQ(fs::path(s.nonlinear.force_curve), fs::path(liver.nonlinear.force_curve));
  EXPECT_EQ(s.fixed.plane_point, liver.fixed.plane_point);

  // The trajectory names the scene's instruments, in order; 10 ms samples, smooth, every input present.
  ASSERT_FALSE(s.trajectory.empty());
  const MultiTrajectory traj = MultiTrajectory::load(s.trajectory);
  ASSERT_EQ(traj.names(), (std::vector<std::string>{"grasper", "probe"}));
  EXPECT_GE(traj.duration(), 4.0);
  EXPECT_LE(traj.duration(), 5.0);
  for (std::size_t k = 0; k < traj.size(); ++k) {
    for (int i = 0; i < 2; ++i) {
      ASSERT_TRUE(traj.valid(k, i));
      if (k > 0) {
        ASSERT_NEAR(traj.times()[k] - traj.times()[k - 1], 0.01, 1e-9);
        ASSERT_LT(std::abs(traj.pose(k, i).insertion - traj.pose(k - 1, i).insertion), 0.001) << k;
      }
    }
  }

  const TetMesh mesh = load_scene_mesh(s, SURGSIM_TEST_CACHE_DIR);
  const SurfaceMesh surface = boundary_surface(mesh);
  // Per instrument and sample: how far the tip is below the rest surface along its shaft (m; < 0: above).
  std::vector<std::vector<double>> depth(2, std::vector<double>(traj.size()));
  std::vector<Eigen::Vector3d> spot(2);
  for (int i = 0; i < 2; ++i) {
    SCOPED_TRACE(s.tools[static_cast<std::size_t>(i)].name);
    for (std::size_t k = 0; k < traj.size(); ++k) {
      const Pose5& p = traj.pose(k, i);
      const ToolGeometry g = tool_geometry(s.tools[static_cast<std::size_t>(i)], p);
      const RayHit hit = first_hit(mesh, surface, g.trocar, g.direction);
      ASSERT_TRUE(hit.found) << "the shaft misses the organ at t = " << traj.times()[k];
      depth[static_cast<std::size_t>(i)][k] = p.insertion - hit.s;
      spot[static_cast<std::size_t>(i)] = hit.point;
    }
    const auto& d = depth[static_cast<std::size_t>(i)];
    EXPECT_LT(d.front(), -0.01) << "starts clear of the surface";
    EXPECT_LT(d.back(), -0.01) << "ends clear of the surface";
    const double deepest = *std::max_element(d.begin(), d.end());
    EXPECT_GT(deepest, 0.001) << "the tip goes below the rest surface";
    EXPECT_LT(deepest, 0.010);
  }
  // The grasp spot is on the free lobe: no fixed node within 1.5 cm of it. The probe presses 2 to 4 cm from it.
  for (int n = 0; n < mesh.nodes.rows(); ++n) {
    const Eigen::Vector3d x = mesh.nodes.row(n).transpose();
    if ((x - spot[0]).norm() < 0.015) {
      EXPECT_FALSE(s.fixed.fixes(n, x)) << "node " << n << " near the grasp is fixed";
    }
  }
  const double apart = (spot[0] - spot[1]).norm();
  EXPECT_GT(apart, 0.02);
  EXPECT_LT(apart, 0.04);

  // The story: the grasper's jaw closes (<= 0.05 rad grasps) while its tip is 1 to 3 mm in; the probe presses while
  // the grasp is held; the probe's jaw never closes (it would grasp); the grasper opens before it withdraws.
  double grasp_depth = -1;
  bool pressed_while_held = false;
  for (std::size_t k = 0; k < traj.size(); ++k) {
    const bool held = traj.pose(k, 0).jaw <= 0.05;
    if (held && grasp_depth < 0) grasp_depth = depth[0][k];
    if (held && depth[1][k] > 0.005) pressed_while_held = true;
    EXPECT_GE(traj.pose(k, 1).jaw, 0.15) << "the probe's jaw closes at t = " << traj.times()[k];
    if (depth[0][k] < -0.01) {
      EXPECT_GT(traj.pose(k, 0).jaw, 0.15) << "withdrawn closed at t = " << traj.times()[k];
    }
  }
  EXPECT_GT(grasp_depth, 0.001);
  EXPECT_LT(grasp_depth, 0.003);
  EXPECT_TRUE(pressed_while_held);
  EXPECT_LT(traj.pose(traj.size() - 1, 0).insertion, traj.pose(traj.size() / 2, 0).insertion);
}

// ---------------------------------------------------------------------------------------------------------------
// Hash

TEST(SceneHash, IgnoresVisualSettingsButNotPhysics) {
  const fs::path dir = test_dir();
  const std::string base = std::string(kMinimal) + "material: {young_modulus: 3000}\n";
  const std::uint64_t h0 = load_scene(write(dir / "a.yaml", base)).hash();
  EXPECT_EQ(h0, load_scene(write(dir / "a2.yaml", base)).hash());  // deterministic

  const std::string visual =
      "visual: {camera: {eye: [1, 2, 3], fov_deg: 50}, png_every: 1, width: 320, vtk: true, rate_hz: 30}\n";
  EXPECT_EQ(h0, load_scene(write(dir / "b.yaml", base + visual)).hash());
  EXPECT_EQ(h0, load_scene(write(dir / "c.yaml",
                                 "name: other_name\nmesh: {generate: liver}\n"
                                 "material: {young_modulus: 3000}\n"))
                    .hash());

  EXPECT_NE(h0, load_scene(write(dir / "d.yaml", std::string(kMinimal) + "material: {young_modulus: 3001}\n")).hash());
  EXPECT_NE(h0, load_scene(write(dir / "e.yaml", base + "haptic: {rate_hz: 1000}\n")).hash());
  // The force stage's keys (the device gets a different force).
  EXPECT_EQ(h0, load_scene(write(dir / "e0.yaml", base + "haptic: {passivity: true, coupling_damping: 3}\n")).hash());
  EXPECT_NE(h0, load_scene(write(dir / "e1.yaml", base + "haptic: {passivity: false}\n")).hash());
  EXPECT_NE(h0, load_scene(write(dir / "e2.yaml", base + "haptic: {coupling_damping: 0}\n")).hash());
  EXPECT_NE(h0, load_scene(write(dir / "e3.yaml", base + "haptic: {passivity_max_damping: 10}\n")).hash());
  // How often the body's state is published: no physics.
  EXPECT_EQ(h0, load_scene(write(dir / "e4.yaml", base + "haptic: {publish_hz: 100}\n")).hash());
  EXPECT_NE(h0, load_scene(write(dir / "f.yaml", base + "tool: {force_limit: 4}\n")).hash());
  EXPECT_NE(h0, load_scene(write(dir / "f1.yaml", base + "tool: {friction: 0.1}\n")).hash());
  EXPECT_NE(h0, load_scene(write(dir / "f2.yaml", base + "tool: {tip_radius: 0.003}\n")).hash());
  EXPECT_NE(h0, load_scene(write(dir / "f3.yaml", base + "tool: {contact_model: triangle}\n")).hash());
  EXPECT_NE(h0, load_scene(write(dir / "g.yaml", base + "fixed: {nodes: [1]}\n")).hash());
  EXPECT_NE(h0, load_scene(write(dir / "h.yaml",
                                 "name: mini\nmesh: {generate: liver, target_nodes: 1400}\n"
                                 "material: {young_modulus: 3000}\n"))
                    .hash());
}

TEST(SceneHash, EveryInstrumentEntersTheHash) {
  const fs::path dir = test_dir();
  const std::string base = std::string(kMinimal) + "material: {young_modulus: 3000}\n";
  const std::string a = "{name: a, trocar: [0, 0, 0.2]}";
  const std::string b = "{name: b, trocar: [0.05, 0, 0.2]}";
  const std::uint64_t one = load_scene(write(dir / "one.yaml", base + "tools: [" + a + "]\n")).hash();
  const std::uint64_t two = load_scene(write(dir / "two.yaml", base + "tools: [" + a + ", " + b + "]\n")).hash();
  EXPECT_NE(one, two);
  // One instrument hashes as the single `tool:` key does (its name aside): scenes written for a single
  // `tool:` key keep theirs.
  EXPECT_EQ(one, load_scene(write(dir / "tool.yaml", base + "tool: {trocar: [0, 0, 0.2]}\n")).hash());
  // The second instrument's settings, its name and the order count.
  EXPECT_NE(two, load_scene(write(dir / "f.yaml", base + "tools: [" + a + ", {name: b, trocar: [0.05, 0, 0.2], "
                                                   "force_limit: 4}]\n"))
                     .hash());
  EXPECT_NE(two, load_scene(write(dir / "n.yaml", base + "tools: [" + a + ", {name: c, trocar: [0.05, 0, 0.2]}]\n"))
                     .hash());
  EXPECT_NE(two, load_scene(write(dir / "o.yaml", base + "tools: [" + b + ", " + a + "]\n")).hash());
}

TEST(SceneHash, IntestineParametersEnterTheHash) {
  const fs::path dir = test_dir();
  const std::string base = "name: gut\nmodel: intestine\n";
  const std::uint64_t h0 = load_scene(write(dir / "a.yaml", base)).hash();
  EXPECT_EQ(h0, load_scene(write(dir / "b.yaml", base + "intestine: {columns: 100}\n")).hash());  // the default
  EXPECT_EQ(h0, load_scene(write(dir / "c.yaml", base + "visual: {target_fps: 20}\n")).hash());
  const Scene scaled = load_scene(write(dir / "s.yaml", base + "visual: {min_render_scale: 0.6}\n"));
  EXPECT_EQ(scaled.visual.min_render_scale, 0.6);
  EXPECT_EQ(load_scene(write(dir / "t.yaml", base)).visual.min_render_scale, 1.0) << "full size unless asked";
  EXPECT_EQ(h0, scaled.hash()) << "the picture's resolution is no physics";
  for (const char* change : {"intestine: {columns: 90}\n", "intestine: {random_pairs: 11}\n", "intestine: {seed: 2}\n",
                             "intestine: {probe_radius: 0.02}\n", "intestine: {gravity: [0, 0, -9]}\n",
                             "intestine: {integrator: symplectic_euler}\n", "intestine: {mesentery_taper: 0.1}\n",
                             "intestine: {obstacle_stiffness: 1000}\n", "intestine: {obstacle_capacity: 10}\n",
                             "tool: {force_limit: 4}\n"}) {
    EXPECT_NE(h0, load_scene(write(dir / "d.yaml", base + change)).hash()) << change;
  }
}

// The obstacle keys of a field are hashed only when not the default: an intestine scene that does not set them keeps
// the hash it had before they existed (taken from haptic_node's stats at fc8bf1b).
TEST(SceneHash, IntestineWithoutObstacleKeysKeepsItsHash) {
  const fs::path dir = test_dir();
  EXPECT_EQ(load_scene(write(dir / "t.yaml", "name: t\nmodel: intestine\n")).hash(), 0xb334b560a7d339a7ULL);
}

TEST(SceneHash, UsesMeshFileNameNotFolder) {
  const fs::path dir = test_dir();
  write(dir / "x" / "organ.msh", "a");
  write(dir / "y" / "organ.msh", "different content");
  write(dir / "y" / "other.msh", "a");
  const auto h1 = load_scene(write(dir / "x" / "s.yaml", "name: s\nmesh: {file: organ.msh}\n")).hash();
  const auto h2 = load_scene(write(dir / "y" / "s.yaml", "name: s\nmesh: {file: organ.msh}\n")).hash();
  const auto h3 = load_scene(write(dir / "y" / "t.yaml", "name: s\nmesh: {file: other.msh}\n")).hash();
  EXPECT_EQ(h1, h2);
  EXPECT_NE(h1, h3);
}

TEST(SceneHash, SingleBoxHashesTheSameLoadedOrBuilt) {
  const fs::path dir = test_dir();
  const Scene loaded =
      load_scene(write(dir / "b.yaml", std::string(kMinimal) + "fixed: {box: {min: [0, 0, 0], max: [1, 1, 1]}}\n"));
  const Scene listed =
      load_scene(write(dir / "l.yaml", std::string(kMinimal) + "fixed: {boxes: [{min: [0, 0, 0], max: [1, 1, 1]}]}\n"));
  Scene built = loaded;
  built.fixed.boxes.assign(1, {Eigen::Vector3d::Zero(), Eigen::Vector3d::Ones()});  // as code might fill it
  EXPECT_EQ(loaded.hash(), built.hash());
  EXPECT_EQ(loaded.hash(), listed.hash());  // `box` is one entry of `boxes`
}

// ---------------------------------------------------------------------------------------------------------------
// Errors: every message names the file, the line and the key.

struct ErrorCase {
  const char* name;
  std::string yaml;
  int line;                  // expected line in "FILE:LINE:", 0 = do not check
  std::string must_contain;  // e.g. the key
  std::string also = "";     // a second fragment (value, hint), optional
};

std::ostream& operator<<(std::ostream& os, const ErrorCase& c) { return os << c.name; }

class SceneError : public ::testing::TestWithParam<ErrorCase> {};

TEST_P(SceneError, NamesFileLineAndKey) {
  const ErrorCase& c = GetParam();
  const fs::path dir = test_dir();
  write(dir / "present.csv", "x\n");
  const std::string path = write(dir / "bad_scene.yaml", c.yaml);
  const std::string msg = load_error(path);
  ASSERT_FALSE(msg.empty()) << "no error for:\n" << c.yaml;
  EXPECT_NE(msg.find("bad_scene.yaml"), std::string::npos) << msg;
  if (c.line > 0) {
    EXPECT_NE(msg.find("bad_scene.yaml:" + std::to_string(c.line) + ":"), std::string::npos) << msg;
  }
  EXPECT_NE(msg.find(c.must_contain), std::string::npos) << msg;
  if (!c.also.empty()) {
    EXPECT_NE(msg.find(c.also), std::string::npos) << msg;
  }
}

const std::string kHead = "name: t\nmesh: {generate: liver}\n";  // 2 lines
const std::string kIntestine = "name: t\nmodel: intestine\n";    // 2 lines
const std::string kVisual = kHead + "visual:\n  camera:\n";      // 4 lines

INSTANTIATE_TEST_SUITE_P(
    Cases, SceneError,
    ::testing::Values(
        // Syntax and structure
        ErrorCase{"YamlSyntax", kHead + "material: {young_modulus: 3000\n", 3, "YAML syntax error"},
        ErrorCase{"BadIndent", "name: t\nmesh:\n  generate: liver\n   target_nodes: 100\n", 4, "YAML syntax error"},
        ErrorCase{"Empty", "", 1, "empty"}, ErrorCase{"NotAMap", "- a\n- b\n", 1, "must be a map"},
        ErrorCase{"MissingName", "mesh: {generate: liver}\n", 1, "key 'name': missing"},
        ErrorCase{"MissingMesh", "name: t\n", 1, "key 'mesh': missing"},
        ErrorCase{"EmptyName", "name: ''\nmesh: {generate: liver}\n", 1, "key 'name'", "empty"},
        ErrorCase{"DuplicateKey", kHead + "name: u\n", 3, "key 'name': duplicate key", "line 1"},
        // Unknown keys with suggestions, at every level
        ErrorCase{"UnknownTop", kHead + "materail: {}\n", 3, "key 'materail': unknown key", "did you mean 'material'"},
        ErrorCase{"UnknownNested", kHead + "material:\n  young_modulus: 3000\n  youngs_modulus: 3000\n", 5,
                  "key 'material.youngs_modulus': unknown key", "did you mean 'young_modulus'"},
        ErrorCase{"UnknownDeep", kHead + "visual:\n  camera: {fovdeg: 30}\n", 4, "key 'visual.camera.fovdeg'",
                  "did you mean 'fov_deg'"},
        ErrorCase{"UnknownInBoxList", kHead + "fixed:\n  boxes:\n    - {min: [0,0,0], mx: [1,1,1]}\n", 5,
                  "key 'fixed.boxes[0].mx'", "did you mean 'max'"},
        ErrorCase{"UnknownFarKey", kHead + "zzzzzzzz: 1\n", 3, "unknown key", "valid keys here: name, model"},
        // Wrong types
        ErrorCase{"StringForNumber", kHead + "material: {young_modulus: soft}\n", 3, "key 'material.young_modulus'",
                  "'soft' is not a number"},
        ErrorCase{"QuotedNumber", kHead + "material: {young_modulus: \"3000\"}\n", 3, "key 'material.young_modulus'",
                  "without quotes"},
        ErrorCase{"ListForNumber", kHead + "haptic: {rate_hz: [300]}\n", 3, "key 'haptic.rate_hz'", "a list"},
        ErrorCase{"MissingNumber", kHead + "haptic: {rate_hz: }\n", 3, "key 'haptic.rate_hz'", "missing value"},
        ErrorCase{"RealForInt", kHead + "tool: {shaft_points: 2.5}\n", 3, "key 'tool.shaft_points'",
                  "expected an integer"},
        ErrorCase{"TwoVector", kHead + "tool: {trocar: [0.03, 0.2]}\n", 3, "key 'tool.trocar'", "got a list of 2"},
        ErrorCase{"StringInVector", kHead + "tool:\n  trocar: [0.03, x, 0.2]\n", 4, "key 'tool.trocar[1]'",
                  "not a number"},
        ErrorCase{"ScalarForVector", kHead + "tool: {axis: 1}\n", 3, "key 'tool.axis'", "expected 3 numbers"},
        ErrorCase{"ScalarForSection", kHead + "material: 3000\n", 3, "key 'material'", "expected a map"},
        ErrorCase{"BadBool", kHead + "visual: {vtk: maybe}\n", 3, "key 'visual.vtk'", "true or false"},
        ErrorCase{"NodesNotList", kHead + "fixed: {nodes: 5}\n", 3, "key 'fixed.nodes'", "expected a list"},
        // Enumerations and mesh source
        ErrorCase{"UnknownModel", kHead + "model: kidney\n", 3, "key 'model'", "liver, intestine"},
        ErrorCase{"UnknownGenerator", "name: t\nmesh: {generate: kidney}\n", 2, "key 'mesh.generate'",
                  "liver, plate, cylinder"},
        ErrorCase{"BothMeshSources", "name: t\nmesh:\n  generate: liver\n  file: present.csv\n", 4, "key 'mesh'",
                  "both"},
        ErrorCase{"NoMeshSource", "name: t\nmesh: {target_nodes: 500}\n", 2, "key 'mesh'", "names no mesh"},
        ErrorCase{"TargetWithFile", "name: t\nmesh: {file: x.msh, target_nodes: 500}\n", 2, "key 'mesh.target_nodes'",
                  "generated"},
        ErrorCase{"MeshFileMissing", "name: t\nmesh:\n  file: meshes/nope.msh\n", 3, "key 'mesh.file'",
                  "meshes/nope.msh' not found"},
        ErrorCase{"MeshFileBadFormat", "name: t\nmesh:\n  file: present.csv\n", 3, "key 'mesh.file'",
                  "unsupported mesh format"},
        // Out of range
        ErrorCase{"PoissonHalf", kHead + "material:\n  poisson_ratio: 0.5\n", 4, "key 'material.poisson_ratio'",
                  "0.5 is out of range [0, 0.5)"},
        ErrorCase{"PoissonNegative", kHead + "material: {poisson_ratio: -0.1}\n", 3, "key 'material.poisson_ratio'",
                  "out of range"},
        ErrorCase{"YoungZero", kHead + "material: {young_modulus: 0}\n", 3, "key 'material.young_modulus'",
                  "0 is out of range (0, inf)"},
        ErrorCase{"YoungInfinite", kHead + "material: {young_modulus: .inf}\n", 3, "key 'material.young_modulus'",
                  "not finite"},
        ErrorCase{"YoungNan", kHead + "material: {young_modulus: .nan}\n", 3, "key 'material.young_modulus'",
                  "not finite"},
        ErrorCase{"YoungOverflow", kHead + "material: {young_modulus: 1e999}\n", 3, "key 'material.young_modulus'",
                  "not finite"},
        ErrorCase{"TargetNodesLow", "name: t\nmesh: {generate: liver, target_nodes: 50}\n", 2,
                  "key 'mesh.target_nodes'", "[100, 100000]"},
        ErrorCase{"TargetNodesHigh", "name: t\nmesh: {generate: liver, target_nodes: 200000}\n", 2,
                  "key 'mesh.target_nodes'", "out of range"},
        ErrorCase{"DegreeHigh", kHead + "nonlinear: {force_curve: present.csv, degree: 11}\n", 3,
                  "key 'nonlinear.degree'", "[4, 10]"},
        ErrorCase{"DegreeLow", kHead + "nonlinear: {force_curve: present.csv, degree: 3}\n", 3,
                  "key 'nonlinear.degree'", "[4, 10]"},
        ErrorCase{"NonlinearWithoutCurve", kHead + "nonlinear: {degree: 6}\n", 3, "key 'nonlinear'", "no curve"},
        ErrorCase{"ShaftPoints", kHead + "tool: {shaft_points: 33}\n", 3, "key 'tool.shaft_points'", "[1, 32]"},
        ErrorCase{"ShaftPointsZero", kHead + "tool: {shaft_points: 0}\n", 3, "key 'tool.shaft_points'", "[1, 32]"},
        ErrorCase{"Capacity", kHead + "tool: {contact_capacity: 0}\n", 3, "key 'tool.contact_capacity'", "[1, 64]"},
        ErrorCase{"CapacityHigh", kHead + "tool: {contact_capacity: 65}\n", 3, "key 'tool.contact_capacity'",
                  "[1, 64]"},
        ErrorCase{"ContactModel", kHead + "tool:\n  contact_model: sphere\n", 4, "key 'tool.contact_model'",
                  "not a contact model"},
        ErrorCase{"TipRadiusNegative", kHead + "tool: {tip_radius: -0.001}\n", 3, "key 'tool.tip_radius'", "(0, 0.1]"},
        // 0 once meant "2.5 mean surface edges"; the radius is now the instrument's own, in metres.
        ErrorCase{"TipRadiusZero", kHead + "tool: {tip_radius: 0}\n", 3, "key 'tool.tip_radius'", "own radius"},
        ErrorCase{"TipRadiusHigh", kHead + "tool: {tip_radius: 1}\n", 3, "key 'tool.tip_radius'", "out of range"},
        ErrorCase{"FrictionNegative", kHead + "tool: {friction: -0.1}\n", 3, "key 'tool.friction'", "[0, 10]"},
        ErrorCase{"FrictionText", kHead + "tool: {friction: sticky}\n", 3, "key 'tool.friction'"},
        // Several instruments
        ErrorCase{"ToolAndTools", kHead + "tool: {force_limit: 4}\ntools: [{name: a}]\n", 4, "key 'tools'",
                  "given together with 'tool' (line 3)"},
        ErrorCase{"ToolsEmpty", kHead + "tools: []\n", 3, "key 'tools': lists 0 instruments", "a list of 1..4"},
        ErrorCase{"ToolsFive", kHead + "tools: [{name: a}, {name: b}, {name: c}, {name: d}, {name: e}]\n", 3,
                  "key 'tools': lists 5 instruments", "a list of 1..4"},
        ErrorCase{"ToolsNotAList", kHead + "tools: {name: a}\n", 3, "key 'tools': expected a list"},
        ErrorCase{"ToolsMissingName", kHead + "tools:\n  - {name: a}\n  - {force_limit: 4}\n", 5,
                  "key 'tools[1].name': missing", "needs a name"},
        ErrorCase{"ToolsDuplicateName", kHead + "tools:\n  - {name: a}\n  - name: a\n", 5, "key 'tools[1].name'",
                  "'a' is also instrument 0"},
        ErrorCase{"ToolsBadNameCharacter", kHead + "tools:\n  - name: left.hand\n", 4, "key 'tools[0].name'",
                  "has the character '.'"},
        ErrorCase{"ToolBadNameCharacter", kHead + "tool: {name: 'a b'}\n", 3, "key 'tool.name'",
                  "has the character ' '"},
        ErrorCase{"ToolsDifferentContactModel",
                  kHead + "tools:\n  - {name: a}\n  - name: b\n    contact_model: triangle\n", 6,
                  "key 'tools[1].contact_model'", "same contact_model"},
        ErrorCase{"ToolsUnknownKey", kHead + "tools:\n  - {name: a, forcelimit: 3}\n", 4, "key 'tools[0].forcelimit'",
                  "did you mean 'force_limit'"},
        ErrorCase{"ToolsBadValue", kHead + "tools:\n  - {name: a}\n  - {name: b, force_limit: 0}\n", 5,
                  "key 'tools[1].force_limit'", "out of range"},
        ErrorCase{"ShaftLength", kHead + "tool: {shaft_length: 0}\n", 3, "key 'tool.shaft_length'", "out of range"},
        ErrorCase{"ShaftRadius", kHead + "tool: {shaft_radius: -1}\n", 3, "key 'tool.shaft_radius'", "out of range"},
        ErrorCase{"ShaftSpacing", kHead + "tool: {shaft_spacing: 0}\n", 3, "key 'tool.shaft_spacing'", "out of range"},
        ErrorCase{"JawLength", kHead + "tool: {jaw_length: 0}\n", 3, "key 'tool.jaw_length'", "out of range"},
        ErrorCase{"ForceLimit", kHead + "tool: {force_limit: 0}\n", 3, "key 'tool.force_limit'", "out of range"},
        ErrorCase{"PointsOffShaft", kHead + "tool: {shaft_points: 32, shaft_spacing: 0.02}\n", 3,
                  "key 'tool.shaft_spacing'", "does not fit"},
        ErrorCase{"ZeroAxis", kHead + "tool: {axis: [0, 0, 0]}\n", 3, "key 'tool.axis'", "zero vector"},
        ErrorCase{"ZeroNormal", kHead + "fixed:\n  plane: {point: [0, 0, 0], normal: [0, 0, 0]}\n", 4,
                  "key 'fixed.plane.normal'", "zero vector"},
        ErrorCase{"PlaneWithoutNormal", kHead + "fixed:\n  plane: {point: [0, 0, 0]}\n", 4, "key 'fixed.plane'",
                  "missing 'normal'"},
        ErrorCase{"BoxInverted", kHead + "fixed:\n  box: {min: [0, 0, 0], max: [1, 0, 1]}\n", 4, "key 'fixed.box.max'",
                  "not above min in y"},
        ErrorCase{
            "BoxesInverted",
            kHead +
                "fixed:\n  boxes:\n    - {min: [0, 0, 0], max: [1, 1, 1]}\n    - {min: [2, 0, 0], max: [1, 1, 1]}\n",
            6, "key 'fixed.boxes[1].max'", "not above min in x"},
        ErrorCase{"BoxWithoutMax", kHead + "fixed: {box: {min: [0, 0, 0]}}\n", 3, "key 'fixed.box'", "missing 'max'"},
        ErrorCase{"NegativeNode", kHead + "fixed: {nodes: [0, -1]}\n", 3, "key 'fixed.nodes[1]'", "out of range"},
        ErrorCase{"HapticRateLow", kHead + "haptic: {rate_hz: 10}\n", 3, "key 'haptic.rate_hz'", "[50, 20000]"},
        ErrorCase{"HapticRateHigh", kHead + "haptic: {rate_hz: 1e6}\n", 3, "key 'haptic.rate_hz'", "out of range"},
        ErrorCase{"Passivity", kHead + "haptic:\n  passivity: maybe\n", 4, "key 'haptic.passivity'", "not a boolean"},
        ErrorCase{"CouplingDampingNegative", kHead + "haptic: {coupling_damping: -1}\n", 3,
                  "key 'haptic.coupling_damping'", "[0, 1000]"},
        ErrorCase{"CouplingDampingText", kHead + "haptic: {coupling_damping: soft}\n", 3,
                  "key 'haptic.coupling_damping'"},
        ErrorCase{"PassivityMaxDampingZero", kHead + "haptic: {passivity_max_damping: 0}\n", 3,
                  "key 'haptic.passivity_max_damping'", "(0, 1000]"},
        ErrorCase{"PassivityMaxDampingHigh", kHead + "haptic:\n  rate_hz: 1000\n  passivity_max_damping: 1e4\n", 5,
                  "key 'haptic.passivity_max_damping'", "out of range"},
        ErrorCase{"PublishRateNegative", kHead + "haptic: {publish_hz: -5}\n", 3, "key 'haptic.publish_hz'",
                  "[0, 20000]"},
        ErrorCase{"PublishRateAboveTheHapticRate", kHead + "haptic:\n  rate_hz: 500\n  publish_hz: 1000\n", 5,
                  "key 'haptic.publish_hz'", "within 1..rate_hz (500)"},
        ErrorCase{"PublishRateBelowOne", kHead + "haptic: {publish_hz: 0.5}\n", 3, "key 'haptic.publish_hz'",
                  "not 0 or within"},
        ErrorCase{"HapticUnknownKey", kHead + "haptic: {coupling_stiffness: 100}\n", 3, "coupling_stiffness"},
        ErrorCase{"VisualRate", kHead + "visual: {rate_hz: 0}\n", 3, "key 'visual.rate_hz'", "[1, 1000]"},
        ErrorCase{"Width", kHead + "visual: {width: 8}\n", 3, "key 'visual.width'", "[16, 8192]"},
        ErrorCase{"Height", kHead + "visual: {height: 10000}\n", 3, "key 'visual.height'", "[16, 8192]"},
        ErrorCase{"Fov", kHead + "visual:\n  camera: {fov_deg: 170}\n", 4, "key 'visual.camera.fov_deg'", "(1, 170)"},
        ErrorCase{"PngEvery", kHead + "visual: {png_every: -1}\n", 3, "key 'visual.png_every'", "out of range"},
        ErrorCase{"EyeAtTarget", kHead + "visual:\n  camera:\n    eye: [0, 0, 0]\n    target: [0, 0, 0]\n", 6,
                  "key 'visual.camera.target'", "equals the camera eye"},
        ErrorCase{"UpAlongView", kHead + "visual:\n  camera:\n    eye: [0, 0, 1]\n    up: [0, 0, 1]\n", 6,
                  "key 'visual.camera.up'", "parallel"},
        // Referenced files
        ErrorCase{"CurveMissing", kHead + "nonlinear:\n  displacement_curve: curves/none.csv\n", 4,
                  "key 'nonlinear.displacement_curve'", "curves/none.csv' not found"},
        ErrorCase{"ForceCurveMissing", kHead + "nonlinear: {force_curve: none.csv}\n", 3, "key 'nonlinear.force_curve'",
                  "not found"},
        ErrorCase{"TrajectoryMissing", kHead + "trajectory: trajectories/none.csv\n", 3, "key 'trajectory'",
                  "not found"},
        ErrorCase{"SurfaceMissing", kHead + "visual: {surface: meshes/none.vtk}\n", 3, "key 'visual.surface'",
                  "not found"},
        ErrorCase{"TrajectoryIsFolder", kHead + "trajectory: .\n", 3, "key 'trajectory'", "not a regular file"},
        // The intestine section
        ErrorCase{"IntestineForLiver", kHead + "intestine: {columns: 100}\n", 3, "key 'intestine'", "model: intestine"},
        ErrorCase{"IntestineUnknownKey", kIntestine + "intestine:\n  colums: 100\n", 4, "key 'intestine.colums'",
                  "did you mean 'columns'"},
        ErrorCase{"IntestineTooManyMasses", kIntestine + "intestine:\n  rows: 5\n  columns: 500\n", 5,
                  "key 'intestine.columns'", "exceed 2048"},
        ErrorCase{"IntestineColumnsLow", kIntestine + "intestine: {columns: 3}\n", 3, "key 'intestine.columns'",
                  "[4, 2048]"},
        ErrorCase{"IntestineRowsLow", kIntestine + "intestine: {rows: 1}\n", 3, "key 'intestine.rows'", "out of range"},
        ErrorCase{"IntestineRadius", kIntestine + "intestine: {intestine_radius: 0}\n", 3,
                  "key 'intestine.intestine_radius'", "out of range"},
        ErrorCase{"IntestineShort", kIntestine + "intestine:\n  length: 0.5\n", 4, "key 'intestine.length'",
                  "does not exceed the arc"},
        ErrorCase{"IntestineObstacleStiffness", kIntestine + "intestine: {obstacle_stiffness: -1}\n", 3,
                  "key 'intestine.obstacle_stiffness'", "out of range"},
        ErrorCase{"IntestineObstacleCapacity", kIntestine + "intestine: {obstacle_capacity: -1}\n", 3,
                  "key 'intestine.obstacle_capacity'", "out of range"},
        ErrorCase{"IntestineTaper", kIntestine + "intestine: {mesentery_taper: 0.5}\n", 3,
                  "key 'intestine.mesentery_taper'", "out of range"},
        ErrorCase{"IntestineTaperNegative", kIntestine + "intestine: {mesentery_taper: -0.1}\n", 3,
                  "key 'intestine.mesentery_taper'", "out of range"},
        ErrorCase{"IntestineSpan", kIntestine + "intestine: {angular_span: 7}\n", 3, "key 'intestine.angular_span'",
                  "out of range"},
        ErrorCase{"IntestineStiffness", kIntestine + "intestine: {structural_stiffness: -1}\n", 3,
                  "key 'intestine.structural_stiffness'", "out of range"},
        ErrorCase{"IntestineMass", kIntestine + "intestine: {mesentery_node_mass: 0}\n", 3,
                  "key 'intestine.mesentery_node_mass'", "out of range"},
        ErrorCase{"IntestineIntegrator", kIntestine + "intestine: {integrator: rk4}\n", 3, "key 'intestine.integrator'",
                  "implicit_euler, symplectic_euler"},
        ErrorCase{"IntestineSeedZero", kIntestine + "intestine: {seed: 0}\n", 3, "key 'intestine.seed'",
                  "out of range"},
        ErrorCase{"IntestinePairs", kIntestine + "intestine: {random_pairs: -1}\n", 3, "key 'intestine.random_pairs'",
                  "out of range"},
        ErrorCase{"IntestineBool", kIntestine + "intestine: {self_collisions: sometimes}\n", 3,
                  "key 'intestine.self_collisions'", "true or false"},
        ErrorCase{"IntestineAxis", kIntestine + "intestine: {axis_direction: [0, 0, 0]}\n", 3,
                  "key 'intestine.axis_direction'", "zero vector"},
        ErrorCase{"TargetFps", kIntestine + "visual: {target_fps: 0}\n", 3, "key 'visual.target_fps'", "[1, 1000]"},
        ErrorCase{"MinRenderScale", kIntestine + "visual: {min_render_scale: 0.1}\n", 3,
                  "key 'visual.min_render_scale'", "[0.25, 1]"},
        // The picture: the scope camera, visual.render, an organ's colour (scene_picture_test.cpp)
        ErrorCase{"EyeAndPort", kVisual + "    eye: [1, 0, 0]\n    port: [0, 0, 1]\n", 6, "key 'visual.camera.port'",
                  "given together with 'eye' (line 5)"},
        ErrorCase{"ScopeKeyWithoutPort", kVisual + "    eye: [1, 0, 0]\n    angle_deg: 30\n", 6,
                  "key 'visual.camera.angle_deg'", "only for a scope camera"},
        ErrorCase{"PortWithoutTarget", kVisual + "    port: [0, 0, 1]\n", 4, "key 'visual.camera.target'", "missing"},
        ErrorCase{"PortAtTarget", kVisual + "    port: [0, 0, 1]\n    target: [0, 0, 1]\n", 6,
                  "key 'visual.camera.target'", "equals the port"},
        ErrorCase{"InsertionPastTarget", kVisual + "    port: [0, 0, 0.1]\n    target: [0, 0, 0]\n    insertion: 0.2\n",
                  7, "key 'visual.camera.insertion'", "at or past the target"},
        ErrorCase{"AngleTooLarge", kVisual + "    port: [0, 0, 0.1]\n    target: [0, 0, 0]\n    angle_deg: 80\n", 7,
                  "key 'visual.camera.angle_deg'", "out of range [0, 75]"},
        ErrorCase{"UpAlongShaft", kVisual + "    port: [0, 0, 0.1]\n    target: [0, 0, 0]\n    up: [0, 0, 1]\n", 7,
                  "key 'visual.camera.up'", "parallel to the scope's shaft"},
        ErrorCase{"UnknownRenderKey", kHead + "visual:\n  render:\n    marker: true\n", 5, "key 'visual.render.marker'",
                  "did you mean 'markers'"},
        ErrorCase{"MarkersNotBoolean", kHead + "visual:\n  render: {markers: 2}\n", 4, "key 'visual.render.markers'",
                  "not a boolean"},
        ErrorCase{"FalloffWithStudioLight", kHead + "visual:\n  render:\n    falloff: [1, 0, 10]\n", 5,
                  "key 'visual.render.falloff'", "only for the scope light"},
        ErrorCase{"FalloffZeroConstant", kHead + "visual:\n  render:\n    light: scope\n    falloff: [0, 0, 10]\n", 6,
                  "key 'visual.render.falloff'", "a = 0"},
        ErrorCase{"WetOutOfRange", kHead + "visual:\n  render: {wet: 3}\n", 4, "key 'visual.render.wet'", "[0, 2]"},
        ErrorCase{"ColourOutOfRange", kHead + "colour: [1.2, 0, 0]\n", 3, "key 'colour'", "outside [0, 1]"},
        ErrorCase{"ColourNotThree", kHead + "colour: [1, 0]\n", 3, "key 'colour'", "3 numbers"},
        ErrorCase{"ColourAndColor", kHead + "colour: [1, 0, 0]\ncolor: [1, 0, 0]\n", 4, "key 'color'",
                  "given together with 'colour' (line 3)"},
        ErrorCase{"OrganColourAtTopOfAList",
                  "name: f\ncolour: [1, 0, 0]\norgans:\n  - {name: w, model: rigid, rigid: {generate: plane}}\n", 2,
                  "key 'colour'", "at the top level"},
        ErrorCase{"OrganColourInTheList",
                  "name: f\norgans:\n  - name: w\n    model: rigid\n    rigid: {generate: plane}\n    colour: red\n", 6,
                  "key 'organs[0].colour'", "3 numbers"},
        ErrorCase{"LiverDeformation", kHead + "liver: {deformation: warped}\n", 3, "key 'liver.deformation'",
                  "multirate"},
        ErrorCase{"MultirateWithOrganCurves", kHead + "liver: {deformation: multirate, curves: organ}\n", 3,
                  "key 'liver.deformation'", "the multirate tracker is the non-linear model itself"},
        ErrorCase{"LiverWallReach", kHead + "liver: {wall_reach: 2}\n", 3, "key 'liver.wall_reach'", "0.001..0.5"}),
    [](const ::testing::TestParamInfo<ErrorCase>& info) { return std::string(info.param.name); });

TEST(SceneLoad, LiverMultirateIsReadAndHashed) {
  const fs::path dir = test_dir();
  const Scene linear = load_scene(write(dir / "linear.yaml", kMinimal));
  const Scene multirate = load_scene(write(dir / "multirate.yaml", std::string(kMinimal) + "liver: {deformation: multirate}\n"));
  EXPECT_EQ(multirate.liver.deformation, LiverDeformation::kMultirate);
  EXPECT_STREQ(to_string(multirate.liver.deformation), "multirate");
  EXPECT_NE(linear.hash(), multirate.hash());
}

TEST(SceneLoad, MissingFileIsAnErrorNamingIt) {
  const fs::path dir = test_dir();
  const std::string msg = load_error((dir / "no_such_scene.yaml").string());
  EXPECT_NE(msg.find("no_such_scene.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find("cannot open"), std::string::npos) << msg;
}

TEST(SceneLoad, FolderIsAnError) {
  const fs::path dir = test_dir();
  EXPECT_NE(load_error(dir.string()).find("folder"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------------------------
// config_dir and resolve_scene_path

// Sets an environment variable for the scope of a test and restores it after.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const std::string& value) : name_(name) {
    const char* old = std::getenv(name);
    had_ = old != nullptr;
    if (had_) old_ = old;
    setenv(name, value.c_str(), 1);
  }
  ~ScopedEnv() {
    if (had_) {
      setenv(name_, old_.c_str(), 1);
    } else {
      unsetenv(name_);
    }
  }

 private:
  const char* name_;
  bool had_ = false;
  std::string old_;
};

TEST(ConfigDir, EnvironmentOverridesTheBuiltInFolder) {
  const fs::path dir = test_dir();
  {
    ScopedEnv env("SURGSIM_CONFIG_DIR", dir.string());
    EXPECT_EQ(config_dir(), dir.string());
  }
  {
    ScopedEnv env("SURGSIM_CONFIG_DIR", "");
    EXPECT_FALSE(config_dir().empty());
    EXPECT_TRUE(fs::exists(fs::path(config_dir()) / "liver.yaml")) << config_dir();
  }
}

TEST(ResolveScenePath, NamesPathsAndErrors) {
  ScopedEnv env("SURGSIM_CONFIG_DIR", shipped_config_dir());
  // A shipped name, with or without extension.
  EXPECT_EQ(fs::path(resolve_scene_path("liver")), fs::path(shipped_config_dir()) / "liver.yaml");
  EXPECT_EQ(fs::path(resolve_scene_path("plate.yaml")), fs::path(shipped_config_dir()) / "plate.yaml");
  EXPECT_EQ(load_scene(resolve_scene_path("cylinder")).name, "cylinder");

  // An existing file is returned as is (it wins over a shipped scene of the same name).
  const fs::path dir = test_dir();
  const std::string mine = write(dir / "liver", kMinimal);
  EXPECT_EQ(resolve_scene_path(mine), mine);

  // Neither: the error lists the shipped scenes.
  for (const std::string& bad : {std::string("kidney"), (dir / "nope.yaml").string(), std::string()}) {
    try {
      resolve_scene_path(bad);
      ADD_FAILURE() << "no error for '" << bad << "'";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("liver"), std::string::npos) << msg;
      EXPECT_NE(msg.find("plate"), std::string::npos) << msg;
      EXPECT_NE(msg.find("cylinder"), std::string::npos) << msg;
    }
  }
}

}  // namespace
}  // namespace surgsim
