// Tests for common/imaging/segmentation.cpp and the surgsim-segment program: the round trip of the generated liver
// through a voxelization (3 mm voxels, clean and noisy) with its figures, the written mesh and scene (validated,
// loaded, and solved in the liver scene's setting), determinism, labels, mirrored axes, and bad volumes refused by
// the program with the file named.
#include "imaging/segmentation.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "support/error_test_util.h"
#include "core/error.h"
#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "imaging_test_util.h"
#include "mesh/mesh.h"
#include "scene/scene.h"
#include "mesher/scene_mesh.h"
#include "fem/static_solver.h"
#include "imaging/volume_io.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::scene;
using namespace surgsim::mesher;
using namespace surgsim::imaging;

namespace surgsim {
namespace {

using test::contains;

namespace fs = std::filesystem;

constexpr double kSpacing = 0.003;  // m: the coarse test resolution
constexpr int kNodes = 1500;

const test::ReferenceOrgan& reference() {
  static const test::ReferenceOrgan r = test::reference_liver(5000);
  return r;
}

struct Case {
  LabelVolume volume;
  Segmentation result;
  test::RoundTrip figures;
};

// The clean and the noisy 3 mm liver, each rebuilt once for the whole file.
const Case& liver_case(bool noisy) {
  static std::unique_ptr<Case> cases[2];
  auto& c = cases[noisy ? 1 : 0];
  if (!c) {
    c = std::make_unique<Case>();
    c->volume = test::liver_volume(reference(), kSpacing, noisy ? 0.3 : 0.0, noisy ? 20 : 0, 1);
    SegmentOptions o;
    o.target_nodes = kNodes;
    c->result = segment_volume(c->volume, o);
    c->figures = test::round_trip(reference(), c->result, kSpacing);
  }
  return *c;
}

// A small organ for the tests that do not need the liver: an ellipsoid with semi-axes 30 x 20 x 12 mm on 2 mm
// voxels, label `label`, centred in a grid with a 3-voxel margin.
LabelVolume ellipsoid_volume(std::int32_t label = 1) {
  LabelVolume v;
  v.grid.size = Eigen::Vector3i(36, 26, 18);
  v.grid.spacing = Eigen::Vector3d::Constant(0.002);
  v.grid.origin = Eigen::Vector3d(-0.035, -0.025, -0.017);
  v.labels.assign(static_cast<std::size_t>(v.grid.voxel_count()), 0);
  v.source = "ellipsoid";
  for (int k = 0; k < v.grid.size.z(); ++k)
    for (int j = 0; j < v.grid.size.y(); ++j)
      for (int i = 0; i < v.grid.size.x(); ++i) {
        const Eigen::Vector3d p = v.grid.to_world(Eigen::Vector3d(i, j, k).cwiseProduct(v.grid.spacing));
        const double r = std::pow(p.x() / 0.030, 2) + std::pow(p.y() / 0.020, 2) + std::pow(p.z() / 0.012, 2);
        if (r <= 1.0) v.labels[static_cast<std::size_t>(v.grid.index(i, j, k))] = label;
      }
  return v;
}

fs::path temp_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("surgsim_segment_" + std::to_string(::getpid()) + "_" + name);
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

// Runs a command; returns its exit status and its stdout + stderr.
std::pair<int, std::string> run(const std::string& command) {
  std::string out;
  std::FILE* p = ::popen((command + " 2>&1").c_str(), "r");
  if (p == nullptr) return {-1, ""};
  std::array<char, 4096> buf;
  std::size_t n = 0;
  while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) out.append(buf.data(), n);
  const int status = ::pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

const std::string kProgram = std::string(SURGSIM_TEST_BIN_DIR) + "/surgsim-segment";

class SegmentationRoundTrip : public ::testing::TestWithParam<bool> {};

TEST_P(SegmentationRoundTrip, RebuildsTheLiverCloseLightAndValid) {
  const Case& c = liver_case(GetParam());
  const test::RoundTrip& f = c.figures;
  const SegmentReport& r = c.result.report;
  std::printf("[ figures  ] %s 3 mm: marching cubes %d triangles (H %.2f, mean %.2f voxels, dV %+.2f %%); surface %d "
              "(H %.2f, mean %.2f, dV %+.2f %%); mesh boundary %d (H %.2f, mean %.2f), %d nodes, %d tets, dV %+.2f %%\n",
              GetParam() ? "noisy" : "clean", f.mc_triangles, f.mc_hausdorff, f.mc_mean, 100 * f.mc_volume_error,
              f.surface_triangles, f.surface_hausdorff, f.surface_mean, 100 * f.surface_volume_error,
              f.mesh_triangles, f.mesh_hausdorff, f.mesh_mean, r.mesh.nodes, r.mesh.tets, 100 * f.mesh_volume_error);
  std::printf("[ times    ]");
  for (const StageTime& s : r.stages) std::printf(" %s %.2f s;", s.name.c_str(), s.seconds);
  std::printf("\n");
  // Close to the original: within 2 voxels everywhere, a fraction of a voxel on average.
  EXPECT_LE(f.surface_hausdorff, 2.0);
  EXPECT_LE(f.mesh_hausdorff, 2.0);
  EXPECT_LE(f.surface_mean, 0.35);
  EXPECT_LE(f.mesh_mean, 0.35);
  // Light: well below marching cubes.
  EXPECT_LE(f.surface_triangles, f.mc_triangles / 4);
  EXPECT_LT(f.mesh_triangles, f.surface_triangles);
  // The volume.
  EXPECT_LE(std::fabs(f.surface_volume_error), 0.05);
  EXPECT_LE(std::fabs(f.mesh_volume_error), 0.05);
  // The mesh: the node count asked for, valid as it is, closed and sphere-like.
  EXPECT_NEAR(static_cast<double>(c.result.mesh.nodes.rows()) / kNodes, 1.0, 0.2);
  TetMesh copy = c.result.mesh;
  MeshValidation strict;
  strict.fix_orientation = false;
  EXPECT_NO_THROW(validate_mesh(copy, strict));
  EXPECT_GT(r.mesh.min_quality, 0.05);
  const TriSurfaceTopology t = tri_surface_topology(test::boundary_tri_surface(c.result.mesh));
  EXPECT_TRUE(t.closed_manifold());
  EXPECT_EQ(t.euler, 2);
  // The noise filtered out (on the clean volume the filter only rounds a few corners): one sphere-like surface.
  EXPECT_GT(r.denoised_voxels, GetParam() ? 1000 : 0);
  EXPECT_LT(r.denoised_voxels, GetParam() ? 20000 : 1000);
  EXPECT_EQ(r.genus, 0);
  // Every stage reported.
  ASSERT_EQ(r.stages.size(), 5u);
  EXPECT_EQ(r.stages.front().name, "select");
  EXPECT_EQ(r.stages.back().name, "tetrahedralize");
}

INSTANTIATE_TEST_SUITE_P(Liver3mm, SegmentationRoundTrip, ::testing::Values(false, true),
                         [](const auto& info) { return info.param ? "Noisy" : "Clean"; });

TEST(Segmentation, WrittenSceneLoadsAndSolvesInTheLiverSetting) {
  const Case& c = liver_case(false);
  const fs::path dir = temp_dir("scene");
  const SegmentationFiles files = write_segmentation(c.result, (dir / "rebuilt").string());
  for (const std::string& f : {files.msh, files.vtk, files.surface_vtk, files.scene}) EXPECT_TRUE(fs::exists(f)) << f;
  EXPECT_EQ(read_mesh(files.vtk).tets.rows(), c.result.mesh.tets.rows());

  const Scene scene = load_scene(files.scene);
  EXPECT_EQ(scene.name, "rebuilt");
  EXPECT_EQ(fs::path(scene.mesh.file), fs::path(files.msh));
  const TetMesh mesh = load_scene_mesh(scene, dir.string());
  EXPECT_EQ(mesh.nodes.rows(), c.result.mesh.nodes.rows());

  // The liver scene's physics on it: the underside clamped, the top pushed down 5 mm under the tool.
  const FixedSet fixed = fixed_set_from_region(mesh, scene.fixed);
  EXPECT_GE(static_cast<int>(fixed.fixed_nodes().size()), 3);
  const ElasticModel model = build_elastic_model(mesh, scene.material, fixed, scene.file);
  Eigen::Index top = 0;
  mesh.nodes.col(2).maxCoeff(&top);
  EXPECT_NEAR(scene.tools[0].trocar.x(), mesh.nodes(top, 0), 1e-3);
  StaticSolver solver(model);
  ImposedDisplacement push;
  push.node = static_cast<int>(top);
  push.value = Eigen::Vector3d(0, 0, -0.005);
  const StaticSolution s = solver.solve({push});
  EXPECT_TRUE(s.displacement.allFinite());
  EXPECT_LT(s.total_reaction.z(), 0.0);  // the constraint pushes the organ down
  fs::remove_all(dir);
}

TEST(Segmentation, IsDeterministic) {
  const LabelVolume v = ellipsoid_volume();
  SegmentOptions o;
  o.target_nodes = 400;
  const Segmentation a = segment_volume(v, o), b = segment_volume(v, o);
  EXPECT_EQ(mesh_hash(a.mesh), mesh_hash(b.mesh));
  EXPECT_EQ(a.surface.vertices, b.surface.vertices);
  EXPECT_EQ(a.surface.tris, b.surface.tris);
}

TEST(Segmentation, SelectsAnOrganByLabelAndKeepsMirroredAxesOutward) {
  // The organ as label 3 next to a box labelled 7, with the j axis running along -y (a reflection).
  LabelVolume v = ellipsoid_volume(3);
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i) v.labels[static_cast<std::size_t>(v.grid.index(i, j, k))] = 7;
  v.grid.axes(1, 1) = -1.0;
  SegmentOptions o;
  o.target_nodes = 400;
  o.label = 3;
  const Segmentation s = segment_volume(v, o);
  EXPECT_EQ(s.report.label, 3);
  EXPECT_GT(tri_surface_volume(s.surface), 0.0);
  EXPECT_NEAR(s.report.mesh_volume, s.report.voxel_volume, 0.05 * s.report.voxel_volume);
  // Mirrored: the mesh lies on the other side of y = origin.
  EXPECT_LT(s.mesh.nodes.col(1).maxCoeff(), v.grid.origin.y() + 1e-9);
  o.label = 4;
  try {
    segment_volume(v, o);
    ADD_FAILURE() << "label 4 accepted";
  } catch (const Error& e) {
    EXPECT_TRUE(contains(e.what(), "ellipsoid") && contains(e.what(), "label 4 not present") &&
                contains(e.what(), "3 (") && contains(e.what(), "7 ("))
        << e.what();
  }
}

TEST(SurgsimSegment, BuildsFromPngSlicesAndPrintsEachStage) {
  const fs::path dir = temp_dir("cli");
  write_png_slices(ellipsoid_volume(), (dir / "slices").string());
  const auto [status, out] = run(kProgram + " --slices " + (dir / "slices").string() +
                                 " --spacing 2,2,2 --nodes 400 --out " + (dir / "organ").string());
  ASSERT_EQ(status, 0) << out;
  for (const char* stage : {"read:", "select:", "marching cubes:", "smooth:", "reduce:", "tetrahedralize:", "write:",
                            "summary:"})
    EXPECT_TRUE(contains(out, stage)) << stage << " missing in\n" << out;
  for (const char* f : {"organ.msh", "organ.vtk", "organ_surface.vtk", "organ.yaml"})
    EXPECT_TRUE(fs::exists(dir / f)) << f;
  EXPECT_NO_THROW(load_scene((dir / "organ.yaml").string()));
  const auto [help_status, help] = run(kProgram + " --help");
  EXPECT_EQ(help_status, 0);
  EXPECT_TRUE(contains(help, "--slices") && contains(help, "--nrrd") && contains(help, "--max-distance")) << help;
  fs::remove_all(dir);
}

TEST(SurgsimSegment, RefusesBadVolumesNamingTheFile) {
  const fs::path dir = temp_dir("bad");
  auto expect_refused = [&](const std::string& args, const std::string& file, const std::string& what) {
    const auto [status, out] = run(kProgram + " " + args + " --out " + (dir / "out").string());
    EXPECT_EQ(status, 1) << args << "\n" << out;
    EXPECT_TRUE(contains(out, "surgsim-segment: ") && contains(out, file) && contains(out, what))
        << args << "\n" << out;
    EXPECT_FALSE(fs::exists(dir / "out.msh"));
  };
  // Empty (no foreground) and all foreground.
  LabelVolume v;
  v.grid.size = Eigen::Vector3i(6, 5, 4);
  v.grid.spacing = Eigen::Vector3d::Constant(0.001);
  v.labels.assign(120, 0);
  write_nrrd(v, (dir / "empty.nrrd").string());
  expect_refused("--nrrd " + (dir / "empty.nrrd").string(), (dir / "empty.nrrd").string(), "no foreground");
  v.labels.assign(120, 2);
  write_nrrd(v, (dir / "full.nrrd").string());
  expect_refused("--nrrd " + (dir / "full.nrrd").string(), (dir / "full.nrrd").string(), "every voxel is foreground");
  // A label that does not exist.
  for (int i = 0; i < 60; ++i) v.labels[static_cast<std::size_t>(i)] = 0;
  write_nrrd(v, (dir / "two.nrrd").string());
  expect_refused("--nrrd " + (dir / "two.nrrd").string() + " --label 9", (dir / "two.nrrd").string(),
                 "label 9 not present; labels present: 0 (60 voxels), 2 (60 voxels)");
  // Mismatched slice sizes, a missing slice.
  write_png_slices(v, (dir / "sizes").string());
  LabelVolume wide = v;
  wide.grid.size = Eigen::Vector3i(7, 5, 1);
  wide.labels.assign(35, 1);
  write_png_slices(wide, (dir / "wide").string());
  fs::copy_file(dir / "wide" / "slice_0000.png", dir / "sizes" / "slice_0002.png", fs::copy_options::overwrite_existing);
  expect_refused("--slices " + (dir / "sizes").string() + " --spacing 1,1,1", (dir / "sizes" / "slice_0002.png").string(),
                 "7 x 5 pixels");
  write_png_slices(v, (dir / "gap").string());
  fs::remove(dir / "gap" / "slice_0002.png");
  expect_refused("--slices " + (dir / "gap").string() + " --spacing 1,1,1", (dir / "gap").string(), "missing slice 2");
  // A truncated raw file; an NRRD header with an unknown field value.
  NrrdWriteOptions detached;
  detached.detached = true;
  write_nrrd(v, (dir / "cut.nhdr").string(), detached);
  fs::resize_file(dir / "cut.raw", 50);
  expect_refused("--nrrd " + (dir / "cut.nhdr").string(), (dir / "cut.raw").string(), "truncated");
  {
    std::ofstream f(dir / "odd.nrrd", std::ios::binary);
    f << "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 6 5 4\nspacings: 1 1 1\nencoding: bzip2\n\n";
  }
  expect_refused("--nrrd " + (dir / "odd.nrrd").string(), (dir / "odd.nrrd").string() + ":6:", "encoding 'bzip2'");
  // Usage errors exit 2.
  EXPECT_EQ(run(kProgram + " --nrrd x.nrrd --slices y --spacing 1,1,1 --out z").first, 2);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace surgsim
