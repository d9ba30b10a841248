// Tests for common/mesher/organ_mesher.cpp: node-count control, validity, closed outward boundary, volumes,
// determinism, the liver's lobed (non-convex) shape, the on-disk cache (its key and checksum) and spec errors.
#include "mesher/organ_mesher.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <string>
#include <thread>

#include "core/error.h"
#include "mesh/mesh.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::mesher;

namespace surgsim {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kTarget = 500;

struct Generated {
  TetMesh mesh;
  OrganMeshReport report;
  std::string log;  // progress lines and Gmsh's log
};

// One mesh per shape at kTarget nodes, generated once for the whole file (meshing is the slow part).
const Generated& organ(const std::string& shape) {
  static std::map<std::string, Generated> cache;
  auto it = cache.find(shape);
  if (it == cache.end()) {
    Generated g;
    std::ostringstream log;
    g.mesh = generate_organ(OrganSpec{shape, kTarget}, &log, &g.report);
    g.log = log.str();
    it = cache.emplace(shape, std::move(g)).first;
  }
  return it->second;
}

// Volume enclosed by the boundary, by the divergence theorem (positive only if the faces point outward).
double boundary_volume(const TetMesh& mesh, const SurfaceMesh& surface) {
  double v = 0.0;
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f) {
    const Eigen::Vector3d a = mesh.nodes.row(surface.tris(f, 0));
    const Eigen::Vector3d b = mesh.nodes.row(surface.tris(f, 1));
    const Eigen::Vector3d c = mesh.nodes.row(surface.tris(f, 2));
    v += a.dot(b.cross(c)) / 6.0;
  }
  return v;
}

double tets_volume(const TetMesh& mesh) {
  double v = 0.0;
  for (int t = 0; t < mesh.tets.rows(); ++t) v += tet_volume(mesh, t);
  return v;
}

// Height (m) of the boundary above (x, y): of the upward-facing faces (top) or the downward-facing ones (bottom);
// NaN if no such face covers (x, y).
double surface_height(const TetMesh& mesh, const SurfaceMesh& surface, double x, double y, bool top) {
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f) {
    const Eigen::Vector3d a = mesh.nodes.row(surface.tris(f, 0));
    const Eigen::Vector3d b = mesh.nodes.row(surface.tris(f, 1));
    const Eigen::Vector3d c = mesh.nodes.row(surface.tris(f, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a);
    if ((n.z() > 0.0) != top || n.z() == 0.0) continue;
    // Barycentric coordinates of (x, y) in the face's projection on the xy-plane.
    const double det = (b.x() - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (b.y() - a.y());
    const double l1 = ((x - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (y - a.y())) / det;
    const double l2 = ((b.x() - a.x()) * (y - a.y()) - (x - a.x()) * (b.y() - a.y())) / det;
    if (l1 >= 0.0 && l2 >= 0.0 && l1 + l2 <= 1.0) return a.z() + l1 * (b.z() - a.z()) + l2 * (c.z() - a.z());
  }
  return std::nan("");
}

// Front edge of the footprint: the smallest y of the boundary nodes within 5 mm of x.
double front_edge(const TetMesh& mesh, const SurfaceMesh& surface, double x) {
  double y = 1.0;
  for (int i : surface.nodes)
    if (std::fabs(mesh.nodes(i, 0) - x) < 0.005) y = std::min(y, mesh.nodes(i, 1));
  return y;
}

class OrganMesherTest : public ::testing::TestWithParam<std::string> {};

TEST_P(OrganMesherTest, HitsTheNodeCountAndIsValid) {
  const Generated& g = organ(GetParam());
  const auto n = g.mesh.nodes.rows();
  EXPECT_NEAR(static_cast<double>(n) / kTarget, 1.0, 0.2) << n << " nodes";
  EXPECT_EQ(g.report.nodes, n);
  EXPECT_EQ(g.report.tets, g.mesh.tets.rows());
  EXPECT_GE(g.report.attempts, 1);
  EXPECT_LE(g.report.attempts, 5);
  EXPECT_GT(g.report.mesh_size, 0.0);
  EXPECT_GT(g.report.min_quality, 0.05);

  // Already valid and positively oriented: validation without repair accepts it unchanged.
  TetMesh copy = g.mesh;
  MeshValidation strict;
  strict.fix_orientation = false;
  EXPECT_NO_THROW(validate_mesh(copy, strict));
  EXPECT_EQ(mesh_hash(copy), mesh_hash(g.mesh));
  for (int t = 0; t < g.mesh.tets.rows(); ++t) ASSERT_GT(tet_volume(g.mesh, t), 0.0) << "tet " << t;
}

TEST_P(OrganMesherTest, GmshLogsNoWarningOrError) {
  const Generated& g = organ(GetParam());
  EXPECT_NE(g.log.find("attempt 1"), std::string::npos) << g.log;
  EXPECT_EQ(g.log.find("gmsh: Warning"), std::string::npos) << g.log;
  EXPECT_EQ(g.log.find("gmsh: Error"), std::string::npos) << g.log;
}

TEST_P(OrganMesherTest, BoundaryIsClosedAndOutward) {
  const Generated& g = organ(GetParam());
  const SurfaceMesh surface = boundary_surface(g.mesh);
  ASSERT_GT(surface.tris.rows(), 0);
  // Closed: every boundary edge is shared by exactly two boundary faces.
  std::map<std::pair<int, int>, int> edges;
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f)
    for (int k = 0; k < 3; ++k) ++edges[std::minmax(surface.tris(f, k), surface.tris(f, (k + 1) % 3))];
  for (const auto& [edge, count] : edges) ASSERT_EQ(count, 2) << "edge " << edge.first << "-" << edge.second;
  // Euler characteristic 2: one sphere-like closed surface.
  const auto v = static_cast<long>(surface.nodes.size()), e = static_cast<long>(edges.size());
  EXPECT_EQ(v - e + surface.tris.rows(), 2);
  // Outward: the divergence-theorem volume equals the tets' volume.
  const double vt = tets_volume(g.mesh);
  EXPECT_NEAR(boundary_volume(g.mesh, surface), vt, 1e-9 * vt);
}

INSTANTIATE_TEST_SUITE_P(Shapes, OrganMesherTest, ::testing::Values("plate", "cylinder", "liver"),
                         [](const auto& info) { return info.param; });

TEST(OrganMesher, PlateAndCylinderHaveTheirShapeAndVolume) {
  const TetMesh& plate = organ("plate").mesh;
  EXPECT_NEAR(tets_volume(plate), 0.20 * 0.20 * 0.01, 1e-3 * 4e-4);
  const Eigen::Vector3d plo = plate.nodes.colwise().minCoeff(), phi = plate.nodes.colwise().maxCoeff();
  EXPECT_TRUE(plo.isApprox(Eigen::Vector3d(-0.10, -0.10, -0.005), 1e-9)) << plo.transpose();
  EXPECT_TRUE(phi.isApprox(Eigen::Vector3d(0.10, 0.10, 0.005), 1e-9)) << phi.transpose();

  const TetMesh& cyl = organ("cylinder").mesh;
  const double exact = kPi * 0.025 * 0.025 * 0.10;
  // Chords of the circle cut a little volume off: within 3 % at ~500 nodes.
  EXPECT_NEAR(tets_volume(cyl), exact, 0.03 * exact);
  EXPECT_NEAR(cyl.nodes.col(2).minCoeff(), 0.0, 1e-12);
  EXPECT_NEAR(cyl.nodes.col(2).maxCoeff(), 0.10, 1e-12);
  for (int i = 0; i < cyl.nodes.rows(); ++i) ASSERT_LE(cyl.nodes.row(i).head<2>().norm(), 0.025 + 1e-9);
  // The compressed top and the fixed bottom carry nodes.
  int top = 0, bottom = 0;
  for (int i = 0; i < cyl.nodes.rows(); ++i) {
    top += cyl.nodes(i, 2) > 0.10 - 1e-9;
    bottom += cyl.nodes(i, 2) < 1e-9;
  }
  EXPECT_GT(top, 10);
  EXPECT_GT(bottom, 10);
}

TEST(OrganMesher, LiverHasTheAgreedExtentsTopAndUnderside) {
  const TetMesh& liver = organ("liver").mesh;
  const Eigen::Vector3d lo = liver.nodes.colwise().minCoeff(), hi = liver.nodes.colwise().maxCoeff();
  EXPECT_NEAR(lo.x(), -0.13, 0.01);
  EXPECT_NEAR(hi.x(), 0.13, 0.01);
  EXPECT_NEAR(lo.y(), -0.08, 0.01);
  EXPECT_NEAR(hi.y(), 0.08, 0.01);
  EXPECT_NEAR(lo.z(), -0.036, 0.005);
  EXPECT_NEAR(hi.z(), 0.043, 0.005);
  EXPECT_LT(lo.norm() + hi.norm(), 0.35);
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  EXPECT_LT(centre.norm(), 0.01) << centre.transpose();

  const SurfaceMesh surface = boundary_surface(liver);
  // Where the default tool pokes straight down.
  const double z_top = surface_height(liver, surface, 0.03, 0.0, true);
  EXPECT_GE(z_top, 0.035);
  EXPECT_LE(z_top, 0.045);
  // A broad, flat underside: downward faces below z = -0.03 cover much of the footprint.
  double flat_area = 0.0;
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f) {
    const Eigen::Vector3d a = liver.nodes.row(surface.tris(f, 0));
    const Eigen::Vector3d b = liver.nodes.row(surface.tris(f, 1));
    const Eigen::Vector3d c = liver.nodes.row(surface.tris(f, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a);
    if ((a.z() + b.z() + c.z()) / 3.0 < -0.03 && n.normalized().z() < -0.95) flat_area += 0.5 * n.norm();
  }
  EXPECT_GT(flat_area, 0.01) << "m^2";  // 100 cm^2 of the ~300 cm^2 footprint
}

TEST(OrganMesher, LiverIsNotAnEllipsoid) {
  // Each check fails for any ellipsoid (or convex solid) centred in the liver's bounding box.
  const TetMesh& liver = organ("liver").mesh;
  const SurfaceMesh surface = boundary_surface(liver);
  // The notch: the footprint of a convex solid is convex, so its front edge y(x) is a convex function and
  // y(0) <= (y(-d) + y(d)) / 2. The notch between the lobes puts the front edge at x = 0 centimetres behind that.
  const double notch = front_edge(liver, surface, 0.0);
  const double chord = 0.5 * (front_edge(liver, surface, -0.05) + front_edge(liver, surface, 0.05));
  EXPECT_GT(notch - chord, 0.01) << "front edge at x = 0: " << notch << " m, chord: " << chord << " m";
  // The lobes: the right lobe (x > 0) is thicker than the left one at the same distance from the centre (about
  // 1.45 times at 7 cm; 1 for an ellipsoid).
  const double centre_x = 0.5 * (liver.nodes.col(0).minCoeff() + liver.nodes.col(0).maxCoeff());
  auto thickness = [&](double x) {
    return surface_height(liver, surface, x, 0.0, true) - surface_height(liver, surface, x, 0.0, false);
  };
  const double right = thickness(centre_x + 0.07), left = thickness(centre_x - 0.07);
  EXPECT_GT(right, 1.25 * left) << "thickness at x = +-0.07 from the centre: " << right << ", " << left << " m";
}

TEST(OrganMesher, IsDeterministic) {
  for (const std::string shape : {"plate", "cylinder", "liver"}) {
    const TetMesh again = generate_organ(OrganSpec{shape, kTarget});
    const TetMesh& first = organ(shape).mesh;
    ASSERT_EQ(again.nodes.rows(), first.nodes.rows()) << shape;
    ASSERT_EQ(again.tets.rows(), first.tets.rows()) << shape;
    EXPECT_TRUE(again.nodes == first.nodes) << shape;  // bit-identical
    EXPECT_TRUE(again.tets == first.tets) << shape;
    EXPECT_EQ(mesh_hash(again), mesh_hash(first)) << shape;
  }
}

TEST(OrganMesher, ConcurrentCallsAreSerializedAndGiveTheSameMesh) {
  // Gmsh is global state: generate_organ takes a process-wide lock, so threads may call it.
  TetMesh a, b;
  std::thread ta([&a] { a = generate_organ(OrganSpec{"plate", kTarget}); });
  std::thread tb([&b] { b = generate_organ(OrganSpec{"plate", kTarget}); });
  ta.join();
  tb.join();
  EXPECT_EQ(mesh_hash(a), mesh_hash(organ("plate").mesh));
  EXPECT_EQ(mesh_hash(b), mesh_hash(organ("plate").mesh));
}

TEST(OrganMesher, RefusesABadSpecWithAClearMessage) {
  try {
    generate_organ(OrganSpec{"kidney", kTarget});
    FAIL() << "no error";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("unknown organ shape 'kidney'"), std::string::npos) << what;
    EXPECT_NE(what.find("liver, plate or cylinder"), std::string::npos) << what;
  }
  EXPECT_THROW(generate_organ(OrganSpec{"liver", kMinOrganNodes - 1}), Error);
  EXPECT_THROW(generate_organ(OrganSpec{"liver", kMaxOrganNodes + 1}), Error);
  try {
    check_organ_spec(OrganSpec{"plate", 50});
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("out of range 100..200000"), std::string::npos) << e.what();
  }
  const auto dir = std::filesystem::temp_directory_path() / ("surgsim_organ_bad_" + std::to_string(::getpid()));
  EXPECT_THROW(ensure_organ_mesh(OrganSpec{"kidney", kTarget}, dir.string()), Error);
  EXPECT_FALSE(std::filesystem::exists(dir));
}

TEST(OrganMesher, EnsureOrganMeshGeneratesOnceThenUsesTheCache) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("surgsim_organ_cache_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const OrganSpec spec{"cylinder", kTarget};

  OrganMeshCacheOutcome outcome;
  const std::string path = ensure_organ_mesh(spec, dir.string(), nullptr, &outcome);
  EXPECT_TRUE(outcome.generated);
  EXPECT_EQ(outcome.rejected, "");
  const std::string name = "cylinder-500-g" + std::to_string(kOrganMeshVersion);
  EXPECT_EQ(path, (dir / (name + ".msh")).string());
  EXPECT_EQ(path, organ_mesh_path(spec, dir.string()));
  ASSERT_TRUE(fs::is_regular_file(path));
  EXPECT_TRUE(fs::is_regular_file(dir / (name + ".vtk")));
  // Only the two published files: no temporary left behind.
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()), 2);
  // The file holds the generated mesh exactly.
  const TetMesh read = read_mesh(path);
  EXPECT_EQ(mesh_hash(read), mesh_hash(organ("cylinder").mesh));

  const auto mtime = fs::last_write_time(path);
  outcome.generated = true;
  EXPECT_EQ(ensure_organ_mesh(spec, dir.string(), nullptr, &outcome), path);
  EXPECT_FALSE(outcome.generated);
  EXPECT_EQ(outcome.rejected, "");
  EXPECT_EQ(fs::last_write_time(path), mtime);
  fs::remove_all(dir);
}

std::string read_text(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << text;
}

// Seals a cached mesh whose $SurgsimOrganMesh lines a test changed, as organ_mesher.h documents the section: the
// checksum line holds the FNV-1a hash of every byte before it (the hash written out here, not taken from the mesher).
std::string reseal(std::string text) {
  const std::size_t at = text.rfind("checksum ");
  std::uint64_t h = 1469598103934665603ull;
  for (std::size_t i = 0; i < at; ++i) {
    h ^= static_cast<unsigned char>(text[i]);
    h *= 1099511628211ull;
  }
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
  return text.replace(at + 9, 16, hex);
}

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return at == std::string::npos ? text : text.replace(at, from.size(), to);
}

// A cached mesh that was altered, cut short or cached before the files carried a checksum is refused, said on the
// progress stream with its path, and generated again (to the same bytes: the mesher is deterministic); never used.
TEST(OrganMesher, DamagedCachedMeshIsGeneratedAgain) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("surgsim_organ_damaged_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const OrganSpec spec{"cylinder", kTarget};
  const std::string path = ensure_organ_mesh(spec, dir.string());
  const std::string good = read_text(path);
  EXPECT_EQ(cached_organ_mesh_problem(path, spec), "");

  // One digit of the first node's first coordinate: still a valid mesh file, but not the mesh generated.
  std::string altered = good;
  const std::size_t digit = altered.find('.', altered.find("$Nodes")) + 1;
  altered[digit] = altered[digit] == '1' ? '2' : '1';
  const TetMesh generated = read_mesh(path);
  write_msh(path + ".plain.msh", generated);  // as cached before the files carried a checksum
  const std::string plain = read_text(path + ".plain.msh");
  fs::remove(path + ".plain.msh");
  struct Damage {
    const char* what;
    std::string text;
    const char* reason;
  };
  const Damage damages[] = {
      {"a changed digit", altered, "checksum"},
      {"cut inside the elements", good.substr(0, good.find("$Elements") + 100), "no $SurgsimOrganMesh section"},
      {"cut inside the checksum line", good.substr(0, good.rfind("checksum ") + 12), "$SurgsimOrganMesh"},
      {"no checksum (an older cache)", plain, "no $SurgsimOrganMesh section"},
  };
  for (const Damage& d : damages) {
    ASSERT_FALSE(d.text == good) << d.what;  // (== : a failure does not print the files)
    write_text(path, d.text);
    EXPECT_NE(cached_organ_mesh_problem(path, spec), "") << d.what;
    std::ostringstream log;
    OrganMeshCacheOutcome outcome;
    EXPECT_EQ(ensure_organ_mesh(spec, dir.string(), &log, &outcome), path);
    EXPECT_TRUE(outcome.generated) << d.what;
    EXPECT_NE(outcome.rejected.find(d.reason), std::string::npos) << d.what << ": " << outcome.rejected;
    EXPECT_NE(log.str().find(path + " not used"), std::string::npos) << d.what << ": " << log.str();
    EXPECT_NE(log.str().find("generating it again"), std::string::npos) << d.what << ": " << log.str();
    EXPECT_TRUE(read_text(path) == good) << d.what;
  }
  fs::remove_all(dir);
}

// The generator version is part of the key (another version, another file), and a file recording another generator
// version, another Gmsh or another spec (its checksum intact) is refused for that reason.
TEST(OrganMesher, CachedMeshOfAnotherGeneratorOrSpecIsRefused) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("surgsim_organ_foreign_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const OrganSpec spec{"cylinder", kTarget};
  EXPECT_NE(organ_mesh_path(spec, dir.string(), kOrganMeshVersion + 1), organ_mesh_path(spec, dir.string()));
  EXPECT_NE(organ_mesh_path(spec, dir.string()).find("-g" + std::to_string(kOrganMeshVersion) + ".msh"),
            std::string::npos);

  const std::string path = ensure_organ_mesh(spec, dir.string());
  const std::string good = read_text(path);
  ASSERT_NE(good.find("\n$SurgsimOrganMesh\n"), std::string::npos);
  EXPECT_TRUE(reseal(good) == good);  // the test's own checksum agrees with the mesher's
  const std::string version = "generator " + std::to_string(kOrganMeshVersion) + " ";
  const std::string next = "generator " + std::to_string(kOrganMeshVersion + 1) + " ";
  write_text(path, reseal(replaced(good, version, next)));
  OrganMeshCacheOutcome outcome;
  ensure_organ_mesh(spec, dir.string(), nullptr, &outcome);
  EXPECT_TRUE(outcome.generated);
  EXPECT_NE(outcome.rejected.find("generator version " + std::to_string(kOrganMeshVersion + 1)), std::string::npos)
      << outcome.rejected;
  EXPECT_TRUE(read_text(path) == good);

  write_text(path, reseal(replaced(good, " gmsh ", " gmsh 0.0.0-other")));
  EXPECT_NE(cached_organ_mesh_problem(path, spec).find("Gmsh 0.0.0-other"), std::string::npos)
      << cached_organ_mesh_problem(path, spec);
  write_text(path, good);
  const std::string other_spec = cached_organ_mesh_problem(path, OrganSpec{"plate", kTarget});
  EXPECT_NE(other_spec.find("made for cylinder"), std::string::npos) << other_spec;
  EXPECT_NE(cached_organ_mesh_problem(path, OrganSpec{"cylinder", kTarget + 1}), "");
  EXPECT_EQ(cached_organ_mesh_problem(path, spec), "");
  EXPECT_NE(cached_organ_mesh_problem((dir / "none.msh").string(), spec), "");
  fs::remove_all(dir);
}

}  // namespace
}  // namespace surgsim
