#include "mesh/mesh.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <initializer_list>
#include <random>
#include <sstream>
#include <string>

#include "core/error.h"

namespace surgsim {
namespace {

// ---- Fixtures: a unit cube split into 5 tets (4 corner tets + a central one), in every supported format.
// Node order is the same everywhere: (0,0,0) (1,0,0) (1,1,0) (0,1,0) (0,0,1) (1,0,1) (1,1,1) (0,1,1).

TetMesh cube_mesh() {
  TetMesh m;
  m.nodes.resize(8, 3);
  m.nodes << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1;
  m.tets.resize(5, 4);
  m.tets << 0, 1, 3, 4, 2, 3, 1, 6, 5, 1, 4, 6, 7, 4, 3, 6, 1, 3, 4, 6;
  return m;
}

// v1 with gaps in node ids and a point, a line and a triangle to skip. Element 4 (first tet) is on line 17.
const char* const kCubeV1 =
    "$NOD\n"
    "8\n"
    "2 0 0 0\n"
    "5 1 0 0\n"
    "9 1 1 0\n"
    "17 0 1 0\n"
    "22 0 0 1\n"
    "23 1 0 1\n"
    "40 1 1 1\n"
    "41 0 1 1\n"
    "$ENDNOD\n"
    "$ELM\n"
    "8\n"
    "1 15 1 1 1 2\n"
    "2 1 1 1 2 2 5\n"
    "3 2 1 1 3 2 5 9\n"
    "4 4 1 1 4 2 5 17 22\n"
    "5 4 1 1 4 9 17 5 40\n"
    "6 4 1 1 4 23 5 22 40\n"
    "7 4 1 1 4 41 22 17 40\n"
    "8 4 1 1 4 5 17 22 40\n"
    "$ENDELM\n";

// v2.2 with physical names, tags, a triangle and a line to skip, and trailing node data to skip.
const char* const kCubeV2 =
    "$MeshFormat\n"
    "2.2 0 8\n"
    "$EndMeshFormat\n"
    "$PhysicalNames\n"
    "1\n"
    "3 1 \"liver\"\n"
    "$EndPhysicalNames\n"
    "$Nodes\n"
    "8\n"
    "1 0 0 0\n"
    "2 1.0 0 0\n"
    "3 1 1 0\n"
    "4 0 1 0\n"
    "5 0 0 1e0\n"
    "6 1 0 1\n"
    "7 1 1 1\n"
    "8 0 1 1\n"
    "$EndNodes\n"
    "$Elements\n"
    "7\n"
    "1 2 2 0 1 1 2 3\n"
    "2 1 2 0 1 1 2\n"
    "3 4 2 1 1 1 2 4 5\n"
    "4 4 2 1 1 3 4 2 7\n"
    "5 4 2 1 1 6 2 5 7\n"
    "6 4 2 1 1 8 5 4 7\n"
    "7 4 2 1 1 2 4 5 7\n"
    "$EndElements\n"
    "$NodeData\n"
    "1\n"
    "\"displacement\"\n"
    "1\n"
    "0.0\n"
    "3\n"
    "0\n"
    "3\n"
    "1\n"
    "1 0 0 0\n"
    "$EndNodeData\n";

// v4.1: three node blocks (one parametric, with u v), node tags with a gap, point and triangle blocks to skip.
const char* const kCubeV41 =
    "$MeshFormat\n"
    "4.1 0 8\n"
    "$EndMeshFormat\n"
    "$Entities\n"
    "0 0 0 1\n"
    "1 0 0 0 1 1 1 0 0\n"
    "$EndEntities\n"
    "$Nodes\n"
    "3 8 100 200\n"
    "0 1 0 1\n"
    "100\n"
    "0 0 0\n"
    "2 1 1 3\n"
    "101\n"
    "102\n"
    "103\n"
    "1 0 0 0.5 0.5\n"
    "1 1 0 0.1 0.2\n"
    "0 1 0 0 0\n"
    "3 1 0 4\n"
    "104\n"
    "105\n"
    "106\n"
    "200\n"
    "0 0 1\n"
    "1 0 1\n"
    "1 1 1\n"
    "0 1 1\n"
    "$EndNodes\n"
    "$Elements\n"
    "3 7 1 7\n"
    "0 1 15 1\n"
    "1 100 \n"
    "2 1 2 1\n"
    "2 100 101 102 \n"
    "3 1 4 5\n"
    "3 100 101 103 104 \n"
    "4 102 103 101 106 \n"
    "5 105 101 104 106 \n"
    "6 200 104 103 106 \n"
    "7 101 103 104 106 \n"
    "$EndElements\n";

// v4.0: "entity dim parametric n" blocks with "tag x y z" lines.
const char* const kCubeV40 =
    "$MeshFormat\n"
    "4 0 8\n"
    "$EndMeshFormat\n"
    "$Nodes\n"
    "2 8\n"
    "1 0 0 1\n"
    "1 0 0 0\n"
    "1 3 0 7\n"
    "2 1 0 0\n"
    "3 1 1 0\n"
    "4 0 1 0\n"
    "5 0 0 1\n"
    "6 1 0 1\n"
    "7 1 1 1\n"
    "8 0 1 1\n"
    "$EndNodes\n"
    "$Elements\n"
    "1 5\n"
    "1 3 4 5\n"
    "1 1 2 4 5\n"
    "2 3 4 2 7\n"
    "3 6 2 5 7\n"
    "4 8 5 4 7\n"
    "5 2 4 5 7\n"
    "$EndElements\n";

// VTK legacy with a vertex and a triangle cell to skip and cell data to ignore.
const char* const kCubeVtk =
    "# vtk DataFile Version 3.0\n"
    "cube\n"
    "ASCII\n"
    "DATASET UNSTRUCTURED_GRID\n"
    "POINTS 8 float\n"
    "0 0 0 1 0 0 1 1 0\n"
    "0 1 0 0 0 1 1 0 1\n"
    "1 1 1 0 1 1\n"
    "CELLS 7 31\n"
    "1 0\n"
    "3 0 1 2\n"
    "4 0 1 3 4\n"
    "4 2 3 1 6\n"
    "4 5 1 4 6\n"
    "4 7 4 3 6\n"
    "4 1 3 4 6\n"
    "CELL_TYPES 7\n"
    "1\n5\n10\n10\n10\n10\n10\n"
    "CELL_DATA 7\n"
    "SCALARS region int 1\n"
    "LOOKUP_TABLE default\n"
    "0 0 1 1 1 1 1\n";

// VTK 5.1 (offsets + connectivity, metadata block), as written by VTK 9.
const char* const kCubeVtk51 =
    "# vtk DataFile Version 5.1\n"
    "vtk output\n"
    "ASCII\n"
    "DATASET UNSTRUCTURED_GRID\n"
    "POINTS 8 double\n"
    "0 0 0 1 0 0 1 1 0\n"
    "0 1 0 0 0 1 1 0 1\n"
    "1 1 1 0 1 1\n"
    "METADATA\n"
    "INFORMATION 0\n"
    "\n"
    "CELLS 6 20\n"
    "OFFSETS vtktypeint64\n"
    "0 4 8 12 16 20\n"
    "CONNECTIVITY vtktypeint64\n"
    "0 1 3 4 2 3 1 6 5 1 4 6 7 4 3 6 1 3 4 6\n"
    "CELL_TYPES 5\n"
    "10\n10\n10\n10\n10\n";

// ---- Helpers

// Files go under a directory of this process (tests may run in parallel processes), removed at exit.
std::filesystem::path process_dir() {
  return std::filesystem::path(::testing::TempDir()) / ("surgsim_mesh_test_" + std::to_string(::getpid()));
}

class RemoveTestFiles : public ::testing::Environment {
 public:
  void TearDown() override { std::filesystem::remove_all(process_dir()); }
};
[[maybe_unused]] ::testing::Environment* const kRemoveTestFiles =
    ::testing::AddGlobalTestEnvironment(new RemoveTestFiles);

// A directory of its own per test.
std::string test_dir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::filesystem::path dir = process_dir() / (std::string(info->test_suite_name()) + "_" + info->name());
  std::filesystem::create_directories(dir);
  return dir.string();
}

std::string write_file(const std::string& name, const std::string& text) {
  const std::string path = test_dir() + "/" + name;
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string replace(std::string s, const std::string& from, const std::string& to) {
  const auto pos = s.find(from);
  EXPECT_NE(pos, std::string::npos) << "fixture edit: '" << from << "' not found";
  if (pos != std::string::npos) s.replace(pos, from.size(), to);
  return s;
}

// Runs f expecting a surgsim::Error whose message holds every part; returns the message.
std::string expect_error(const std::function<void()>& f, std::initializer_list<std::string> parts) {
  try {
    f();
  } catch (const Error& e) {
    const std::string msg = e.what();
    for (const std::string& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "missing '" << p << "' in: " << msg;
    return msg;
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected surgsim::Error, got another exception: " << e.what();
    return "";
  }
  ADD_FAILURE() << "expected surgsim::Error, nothing was thrown";
  return "";
}

void expect_same_geometry(const TetMesh& a, const TetMesh& b) {
  ASSERT_EQ(a.nodes.rows(), b.nodes.rows());
  ASSERT_EQ(a.tets.rows(), b.tets.rows());
  EXPECT_TRUE(a.nodes == b.nodes);
  EXPECT_TRUE(a.tets == b.tets);
  EXPECT_EQ(mesh_hash(a), mesh_hash(b));
}

double total_volume(const TetMesh& m) {
  double v = 0;
  for (int t = 0; t < m.tets.rows(); ++t) v += tet_volume(m, t);
  return v;
}

// Divergence theorem with F = x / 3 (div F = 1): sum over faces of centroid . n * area / 3 is the enclosed volume
// when every normal points outward.
double divergence_volume(const TetMesh& m, const SurfaceMesh& s) {
  double v = 0;
  for (int f = 0; f < s.tris.rows(); ++f) {
    const Eigen::Vector3d a = m.nodes.row(s.tris(f, 0)).transpose();
    const Eigen::Vector3d b = m.nodes.row(s.tris(f, 1)).transpose();
    const Eigen::Vector3d c = m.nodes.row(s.tris(f, 2)).transpose();
    const Eigen::Vector3d area_normal = 0.5 * (b - a).cross(c - a);  // |.| = area
    v += ((a + b + c) / 3.0).dot(area_normal) / 3.0;
  }
  return v;
}

// n x n x n cubes of side h, 6 tets each (Kuhn/Freudenthal split, conforming); half the tets are inverted.
TetMesh grid_mesh(int n, double h) {
  TetMesh m;
  const int p = n + 1;
  m.nodes.resize(p * p * p, 3);
  for (int k = 0; k < p; ++k) {
    for (int j = 0; j < p; ++j) {
      for (int i = 0; i < p; ++i) m.nodes.row(i + p * (j + p * k)) << i * h, j * h, k * h;
    }
  }
  const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  const int step[3] = {1, p, p * p};
  m.tets.resize(6 * n * n * n, 4);
  int t = 0;
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        for (const auto& perm : perms) {
          int v = i + p * (j + p * k);
          m.tets(t, 0) = v;
          for (int s = 0; s < 3; ++s) m.tets(t, s + 1) = (v += step[perm[s]]);
          ++t;
        }
      }
    }
  }
  return m;
}

// ---- Reading the formats

TEST(ReadMesh, AllFormatsLoadTheSameCube) {
  const TetMesh expected = cube_mesh();
  const TetMesh v1 = read_mesh(write_file("cube_v1.msh", kCubeV1));
  const TetMesh v2 = read_mesh(write_file("cube_v2.msh", kCubeV2));
  const TetMesh v41 = read_mesh(write_file("cube_v41.msh", kCubeV41));
  const TetMesh v40 = read_mesh(write_file("cube_v40.msh", kCubeV40));
  const TetMesh vtk = read_mesh(write_file("cube.vtk", kCubeVtk));
  const TetMesh vtk51 = read_mesh(write_file("cube51.VTK", kCubeVtk51));
  for (const TetMesh* m : {&v1, &v2, &v41, &v40, &vtk, &vtk51}) {
    SCOPED_TRACE(m->source);
    expect_same_geometry(*m, expected);
    EXPECT_NEAR(total_volume(*m), 1.0, 1e-15);
  }
  // File ids are kept for messages, gaps compacted away in the indices.
  EXPECT_EQ(v1.ids, (std::vector<std::int64_t>{2, 5, 9, 17, 22, 23, 40, 41}));
  EXPECT_EQ(v1.tet_ids, (std::vector<std::int64_t>{4, 5, 6, 7, 8}));
  EXPECT_EQ(v2.ids, (std::vector<std::int64_t>{1, 2, 3, 4, 5, 6, 7, 8}));
  EXPECT_EQ(v2.tet_ids, (std::vector<std::int64_t>{3, 4, 5, 6, 7}));
  EXPECT_EQ(v41.ids, (std::vector<std::int64_t>{100, 101, 102, 103, 104, 105, 106, 200}));
  EXPECT_EQ(v41.tet_ids, (std::vector<std::int64_t>{3, 4, 5, 6, 7}));
  EXPECT_EQ(vtk.ids, (std::vector<std::int64_t>{0, 1, 2, 3, 4, 5, 6, 7}));
  EXPECT_EQ(vtk.tet_ids, (std::vector<std::int64_t>{2, 3, 4, 5, 6}));
  EXPECT_NE(v1.source.find("cube_v1.msh"), std::string::npos);
}

TEST(ReadMesh, CrlfLineEndsAndNoFinalNewline) {
  std::string text = kCubeV1;
  std::string crlf;
  for (char c : text) crlf += c == '\n' ? std::string("\r\n") : std::string(1, c);
  crlf.resize(crlf.size() - 2);  // "...$ENDELM" without a final line end
  expect_same_geometry(read_msh(write_file("crlf.msh", crlf)), cube_mesh());
}

TEST(ReadMesh, ValidatesAndHashesDeterministically) {
  TetMesh a = read_mesh(write_file("a.msh", kCubeV2));
  TetMesh b = read_mesh(write_file("b.msh", kCubeV2));
  validate_mesh(a);
  validate_mesh(b);
  EXPECT_EQ(mesh_hash(a), mesh_hash(b));
  b.nodes(3, 1) += 1e-12;
  EXPECT_NE(mesh_hash(a), mesh_hash(b));
  TetMesh c = a;
  std::swap(c.tets(0, 1), c.tets(0, 2));
  EXPECT_NE(mesh_hash(a), mesh_hash(c));
}

// ---- Writing

TEST(WriteMesh, VtkRoundTripIsExact) {
  TetMesh m = grid_mesh(3, 0.1);
  m.nodes(5, 0) += 1.0 / 3000.0;  // a value that needs all 17 digits
  validate_mesh(m);
  const std::string path = test_dir() + "/grid.vtk";
  write_vtk(path, m);
  const TetMesh r = read_vtk(path);
  expect_same_geometry(r, m);
}

TEST(WriteMesh, VtkWithDisplacementField) {
  const TetMesh m = cube_mesh();
  Eigen::MatrixX3d u = Eigen::MatrixX3d::Zero(8, 3);
  u(6, 2) = -0.25;
  const std::string path = test_dir() + "/disp.vtk";
  write_vtk(path, m, &u);
  const std::string text = read_text(path);
  EXPECT_NE(text.find("POINT_DATA 8\nVECTORS displacement double\n"), std::string::npos);
  EXPECT_NE(text.find("0 0 -0.25\n"), std::string::npos);
  expect_same_geometry(read_vtk(path), m);

  const Eigen::MatrixX3d wrong = Eigen::MatrixX3d::Zero(3, 3);
  expect_error([&] { write_vtk(path, m, &wrong); }, {"disp.vtk", "3 rows for 8 nodes"});
  expect_error([&] { write_vtk(path, m, &u, "my field"); }, {"no spaces"});
}

TEST(WriteMesh, MshRoundTripKeepsIds) {
  const TetMesh v1 = read_msh(write_file("gaps.msh", kCubeV1));
  const std::string path = test_dir() + "/out.msh";
  write_msh(path, v1);
  EXPECT_EQ(read_text(path).rfind("$MeshFormat\n2.2 0 8\n", 0), 0u);
  const TetMesh r = read_msh(path);
  expect_same_geometry(r, v1);
  EXPECT_EQ(r.ids, v1.ids);
  EXPECT_EQ(r.tet_ids, v1.tet_ids);

  // VTK indices start at 0, which Gmsh does not allow: the writer numbers from 1.
  const TetMesh vtk = read_vtk(write_file("c.vtk", kCubeVtk));
  write_msh(path, vtk);
  const TetMesh r2 = read_msh(path);
  expect_same_geometry(r2, vtk);
  EXPECT_EQ(r2.ids, (std::vector<std::int64_t>{1, 2, 3, 4, 5, 6, 7, 8}));
}

TEST(WriteMesh, UnwritablePathIsAnError) {
  expect_error([] { write_vtk("/nonexistent-dir/x.vtk", cube_mesh()); }, {"/nonexistent-dir/x.vtk", "cannot open"});
}

// ---- Boundary

TEST(BoundarySurface, CubeHasTwelveOutwardFaces) {
  const TetMesh m = cube_mesh();
  const SurfaceMesh s = boundary_surface(m);
  EXPECT_EQ(s.tris.rows(), 12);
  EXPECT_EQ(s.nodes, (std::vector<int>{0, 1, 2, 3, 4, 5, 6, 7}));
  EXPECT_NEAR(divergence_volume(m, s), 1.0, 1e-14);
  // Each normal points away from the cube's centre.
  const Eigen::Vector3d centre(0.5, 0.5, 0.5);
  for (int f = 0; f < s.tris.rows(); ++f) {
    const Eigen::Vector3d a = m.nodes.row(s.tris(f, 0)).transpose();
    const Eigen::Vector3d b = m.nodes.row(s.tris(f, 1)).transpose();
    const Eigen::Vector3d c = m.nodes.row(s.tris(f, 2)).transpose();
    EXPECT_GT((b - a).cross(c - a).dot((a + b + c) / 3.0 - centre), 0.0) << "face " << f;
  }
}

TEST(BoundarySurface, GridCountsAndOrientationEvenWithInvertedTets) {
  TetMesh m = grid_mesh(3, 0.01);  // 3 cm cube of 1 cm cells
  // Outward orientation comes from geometry, not from the tets' node order.
  const SurfaceMesh before = boundary_surface(m);
  EXPECT_EQ(before.tris.rows(), 6 * 3 * 3 * 2);
  EXPECT_EQ(static_cast<int>(before.nodes.size()), 4 * 4 * 4 - 2 * 2 * 2);
  EXPECT_NEAR(divergence_volume(m, before), 27e-6, 1e-18);

  validate_mesh(m);
  for (int t = 0; t < m.tets.rows(); ++t) EXPECT_GT(tet_volume(m, t), 0.0);
  EXPECT_NEAR(total_volume(m), 27e-6, 1e-18);
  const SurfaceMesh after = boundary_surface(m);
  EXPECT_NEAR(divergence_volume(m, after), 27e-6, 1e-18);
}

TEST(TetVolume, SignFollowsNodeOrder) {
  TetMesh m = cube_mesh();
  EXPECT_NEAR(tet_volume(m, 0), 1.0 / 6.0, 1e-15);
  std::swap(m.tets(0, 2), m.tets(0, 3));
  EXPECT_NEAR(tet_volume(m, 0), -1.0 / 6.0, 1e-15);
}

// ---- Validation

// The cube as if read from "liver.msh" with ids 11..18 and element ids 101..105.
TetMesh named_cube() {
  TetMesh m = cube_mesh();
  m.source = "liver.msh";
  m.ids = {11, 12, 13, 14, 15, 16, 17, 18};
  m.tet_ids = {101, 102, 103, 104, 105};
  return m;
}

TEST(ValidateMesh, NonFiniteCoordinate) {
  TetMesh m = named_cube();
  m.nodes(6, 1) = std::nan("");
  expect_error([&] { validate_mesh(m); }, {"liver.msh", "node 17", "non-finite"});
  TetMesh anon = cube_mesh();
  anon.nodes(2, 0) = INFINITY;
  expect_error([&] { validate_mesh(anon); }, {"<in-memory mesh>", "node index 2", "non-finite"});
}

TEST(ValidateMesh, IndexOutOfRange) {
  TetMesh m = named_cube();
  m.tets(3, 2) = 8;
  expect_error([&] { validate_mesh(m); }, {"liver.msh", "element 104", "node index 8", "8 nodes"});
}

TEST(ValidateMesh, RepeatedNode) {
  TetMesh m = named_cube();
  m.tets(1, 3) = m.tets(1, 0);
  expect_error([&] { validate_mesh(m); }, {"liver.msh", "element 102", "node 13 twice"});
}

TEST(ValidateMesh, ZeroVolume) {
  TetMesh m = named_cube();
  m.nodes.row(6) << 0.25, 0.25, 0.5;  // the far corner onto the plane of nodes 12, 14, 15: the central tet is flat
  expect_error([&] { validate_mesh(m); }, {"liver.msh", "element 105", "(nodes 12 14 15 17)", "zero volume"});
  TetMesh tiny = named_cube();
  tiny.nodes.row(4) << 0, 0, 1e-14;  // element 101 becomes a sliver next to unit-size tets
  MeshValidation opts;
  opts.min_volume_ratio = 1e-9;
  expect_error([&] { validate_mesh(tiny, opts); }, {"liver.msh", "element 101", "zero volume"});
}

TEST(ValidateMesh, InvertedIsRefusedOrFlipped) {
  TetMesh m = named_cube();
  std::swap(m.tets(2, 0), m.tets(2, 1));
  const Eigen::MatrixX4i original = m.tets;
  MeshValidation strict;
  strict.fix_orientation = false;
  expect_error([&] { validate_mesh(m, strict); }, {"liver.msh", "element 103", "inverted", "fix_orientation"});
  EXPECT_TRUE(m.tets == original);  // a refused mesh is left as it was

  validate_mesh(m);
  for (int t = 0; t < m.tets.rows(); ++t) EXPECT_GT(tet_volume(m, t), 0.0) << "tet " << t;
  EXPECT_NEAR(total_volume(m), 1.0, 1e-15);
}

TEST(ValidateMesh, UnreferencedNode) {
  TetMesh m = named_cube();
  m.nodes.conservativeResize(9, 3);
  m.nodes.row(8) << 2, 2, 2;
  m.ids.push_back(99);
  expect_error([&] { validate_mesh(m); }, {"liver.msh", "node 99", "not used by any tetrahedron"});
}

// Two tets meeting along one edge only (nodes 0-1): that edge has 4 boundary faces.
TEST(ValidateMesh, NonManifoldEdge) {
  TetMesh m;
  m.source = "bowtie.msh";
  m.nodes.resize(6, 3);
  m.nodes << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, -1, 0, 0, 0, -1;
  m.tets.resize(2, 4);
  m.tets << 0, 1, 2, 3, 0, 1, 4, 5;
  m.ids = {7, 8, 9, 10, 11, 12};
  m.tet_ids = {1, 2};
  expect_error([&] { validate_mesh(m); },
               {"bowtie.msh", "boundary edge (node 7, node 8)", "4 boundary faces", "element 1", "non-manifold"});
}

TEST(ValidateMesh, FaceSharedByThreeTets) {
  TetMesh m;
  m.nodes.resize(6, 3);
  m.nodes << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -1, 0.2, 0.2, 0.5;
  m.tets.resize(3, 4);
  m.tets << 0, 1, 2, 3, 0, 2, 1, 4, 0, 1, 2, 5;
  expect_error([&] { validate_mesh(m); }, {"<in-memory mesh>", "shared by 3 tets", "tet 0 (0-based)"});
}

TEST(ValidateMesh, NoTets) {
  TetMesh m = cube_mesh();
  m.tets.resize(0, 4);
  expect_error([&] { validate_mesh(m); }, {"<in-memory mesh>", "no tetrahedra"});
}

// ---- Reading errors: FILE:LINE: what

TEST(ReadErrors, UnknownNodeNamesFileLineAndElement) {
  const std::string path = write_file("bad_node.msh", replace(kCubeV1, "4 4 1 1 4 2 5 17 22", "4 4 1 1 4 2 5 999 22"));
  expect_error([&] { read_msh(path); }, {"bad_node.msh:17: element 4 references node 999 which is not in $NOD"});
  const std::string p2 = write_file("bad_node2.msh", replace(kCubeV2, "6 4 2 1 1 8 5 4 7", "6 4 2 1 1 8 5 4 70"));
  expect_error([&] { read_msh(p2); }, {"bad_node2.msh:26: element 6 references node 70 which is not in $Nodes"});
  const std::string p4 = write_file("bad_node4.msh", replace(kCubeV41, "5 105 101 104 106", "5 105 101 104 107"));
  expect_error([&] { read_msh(p4); }, {"bad_node4.msh:39: element 5 references node 107"});
}

TEST(ReadErrors, TruncatedFiles) {
  // Missing $EndNodes and everything after.
  const std::string v2 = kCubeV2;
  const std::string cut = v2.substr(0, v2.find("$EndNodes"));
  expect_error([&] { read_msh(write_file("cut.msh", cut)); }, {"cut.msh:17:", "end of file", "$EndNodes"});
  // Fewer nodes than declared.
  expect_error([&] { read_msh(write_file("few.msh", replace(kCubeV2, "$Nodes\n8\n", "$Nodes\n9\n"))); },
               {"few.msh:18:", "after 8 of 9 declared nodes"});
  // More nodes than declared.
  expect_error([&] { read_msh(write_file("many.msh", replace(kCubeV2, "$Nodes\n8\n", "$Nodes\n7\n"))); },
               {"many.msh:17:", "expected $EndNodes"});
  // Cut in the middle of the elements.
  const std::string v1 = kCubeV1;
  expect_error([&] { read_msh(write_file("cut_elm.msh", v1.substr(0, v1.find("7 4 1 1")))); },
               {"cut_elm.msh:19:", "end of file", "element 7 of 8", "truncated"});
  // v4.1 cut inside a node block.
  const std::string v41 = kCubeV41;
  expect_error([&] { read_msh(write_file("cut41.msh", v41.substr(0, v41.find("1 1 0 0.1")))); },
               {"cut41.msh:", "end of file"});
  // VTK cut inside the points.
  const std::string vtk = kCubeVtk;
  expect_error([&] { read_vtk(write_file("cut.vtk", vtk.substr(0, vtk.find("1 1 1 0")))); },
               {"cut.vtk:7:", "end of file", "point coordinate"});
}

// Every prefix of every fixture is an error or the whole cube, never a partial mesh.
TEST(ReadErrors, EveryPrefixIsRefusedOrComplete) {
  for (const char* fixture : {kCubeV1, kCubeV2, kCubeV41, kCubeV40}) {
    const std::string text = fixture;
    const std::size_t last = text.find_last_not_of(" \r\n");
    for (std::size_t n = 0; n <= last; ++n) {
      // A new name each time: rewriting one file over and over is slow on some file systems.
      const std::string path = write_file("prefix" + std::to_string(n) + ".msh", text.substr(0, n));
      try {
        const TetMesh m = read_msh(path);
        SCOPED_TRACE("prefix of " + std::to_string(n) + " bytes was accepted:\n" + text.substr(0, n));
        expect_same_geometry(m, cube_mesh());  // only a prefix that holds every section may load
      } catch (const Error&) {
      }
    }
    EXPECT_NO_THROW(read_msh(write_file("whole.msh", text.substr(0, last + 1))));
    std::filesystem::remove_all(test_dir());
  }
}

// Garbage: random byte edits of the fixtures and random bytes give surgsim::Error or a mesh, never a crash.
TEST(ReadErrors, GarbageNeverCrashes) {
  std::mt19937 rng(12345);
  const std::string alphabet = std::string("0123456789$-+.e \n\r\tEN", 21) + std::string(1, '\0') + "\xff";
  int refused = 0;
  for (const char* fixture : {kCubeV1, kCubeV2, kCubeV41, kCubeV40, kCubeVtk, kCubeVtk51}) {
    const bool vtk = fixture == kCubeVtk || fixture == kCubeVtk51;
    for (int trial = 0; trial < 300; ++trial) {
      std::string text = fixture;
      const int edits = 1 + static_cast<int>(rng() % 3);
      for (int e = 0; e < edits; ++e) text[rng() % text.size()] = alphabet[rng() % alphabet.size()];
      const std::string path = write_file("fuzz" + std::to_string(trial) + (vtk ? ".vtk" : ".msh"), text);
      try {
        const TetMesh m = read_mesh(path);
        EXPECT_GT(m.tets.rows(), 0);
        EXPECT_EQ(m.nodes.rows(), static_cast<Eigen::Index>(m.ids.size()));
        for (int t = 0; t < m.tets.rows(); ++t) {
          for (int k = 0; k < 4; ++k) ASSERT_TRUE(m.tets(t, k) >= 0 && m.tets(t, k) < m.nodes.rows());
        }
      } catch (const Error& err) {
        ++refused;
        EXPECT_NE(std::string(err.what()).find(path), std::string::npos) << err.what();
      }
    }
    std::filesystem::remove_all(test_dir());
  }
  EXPECT_GT(refused, 0);
  for (int trial = 0; trial < 50; ++trial) {
    std::string text(1 + rng() % 2000, '\0');
    for (char& c : text) c = static_cast<char>(rng() % 256);
    if (trial % 2) text = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n" + text;
    EXPECT_THROW(read_mesh(write_file("random" + std::to_string(trial) + ".msh", text)), Error);
    EXPECT_THROW(read_mesh(write_file("random" + std::to_string(trial) + ".vtk", text)), Error);
  }
  std::filesystem::remove_all(test_dir());
}

TEST(ReadErrors, BinaryFilesAreRefused) {
  const std::string bin = std::string("$MeshFormat\n2.2 1 8\n") + std::string("\x01\0\0\0", 4) + "\n$EndMeshFormat\n";
  expect_error([&] { read_mesh(write_file("bin.msh", bin)); }, {"bin.msh:2:", "binary .msh not supported", "ASCII"});
  expect_error([&] { read_mesh(write_file("bin41.msh", "$MeshFormat\n4.1 1 8\n")); }, {"bin41.msh:2:", "binary"});
  const std::string vtk = replace(kCubeVtk, "ASCII", "BINARY");
  expect_error([&] { read_mesh(write_file("bin.vtk", vtk)); }, {"bin.vtk:3:", "binary VTK not supported"});
}

TEST(ReadErrors, ExtensionEmptyAndMissingFiles) {
  expect_error([] { read_mesh("organ.obj"); }, {"organ.obj", ".obj", ".msh", ".vtk"});
  expect_error([] { read_mesh("organ"); }, {"organ:", ".msh", ".vtk"});
  expect_error([] { read_mesh(test_dir() + "/missing.msh"); }, {"missing.msh", "cannot open"});
  expect_error([] { read_mesh(write_file("empty.msh", "")); }, {"empty.msh", "empty"});
  expect_error([] { read_mesh(write_file("blank.vtk", "\n \n")); }, {"blank.vtk", "empty"});
}

TEST(ReadErrors, NonFiniteCoordinate) {
  expect_error([] { read_msh(write_file("nan.msh", replace(kCubeV1, "23 1 0 1", "23 1 nan 1"))); },
               {"nan.msh:8:", "node 23", "non-finite"});
  expect_error([] { read_vtk(write_file("nan.vtk", replace(kCubeVtk, "1 1 1 0 1 1", "1 1 1 0 inf 1"))); },
               {"nan.vtk:8:", "point 7", "non-finite"});
}

TEST(ReadErrors, MalformedContent) {
  expect_error([] { read_msh(write_file("dup.msh", replace(kCubeV1, "41 0 1 1", "9 0 1 1"))); },
               {"dup.msh:10:", "node 9 is defined twice (first on line 5)"});
  expect_error([] { read_msh(write_file("word.msh", replace(kCubeV1, "22 0 0 1", "22 0 zero 1"))); },
               {"word.msh:7:", "expected a number", "'zero'"});
  expect_error([] { read_msh(write_file("short.msh", replace(kCubeV1, "22 0 0 1", "22 0 0"))); },
               {"short.msh:7:", "missing z coordinate"});
  expect_error(
      [] {
        read_msh(write_file("order2.msh", replace(kCubeV2, "7 4 2 1 1 2 4 5 7", "7 11 2 1 1 2 4 5 7 1 1 1 1 1 1")));
      },
      {"order2.msh:27:", "element 7", "higher-order", "type 11"});
  expect_error([] { read_msh(write_file("v3.msh", replace(kCubeV2, "2.2 0 8", "3.0 0 8"))); },
               {"v3.msh:2:", "version 3.0 is not supported"});
  std::string no_tets =
      "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n$EndNodes\n"
      "$Elements\n1\n1 2 2 0 1 1 2 3\n$EndElements\n";
  expect_error([&] { read_msh(write_file("tri.msh", no_tets)); }, {"tri.msh", "no tetrahedra"});
  expect_error([] { read_msh(write_file("open.msh", std::string(kCubeV2) + "$Comments\nhello\n")); },
               {"open.msh:40:", "$Comments is never closed"});
  expect_error([] { read_msh(write_file("text.msh", "hello world\n")); }, {"text.msh:1:", "not a Gmsh ASCII mesh"});
}

TEST(ReadErrors, MalformedVtk) {
  expect_error([] { read_vtk(write_file("poly.vtk", replace(kCubeVtk, "UNSTRUCTURED_GRID", "POLYDATA"))); },
               {"poly.vtk:4:", "POLYDATA", "UNSTRUCTURED_GRID"});
  expect_error([] { read_vtk(write_file("range.vtk", replace(kCubeVtk, "4 7 4 3 6", "4 7 4 3 60"))); },
               {"range.vtk:15:", "cell 5 references point 60", "8 points"});
  expect_error([] { read_vtk(write_file("types.vtk", replace(kCubeVtk, "CELL_TYPES 7\n1\n", "CELL_TYPES 6\n"))); },
               {"types.vtk:", "CELL_TYPES lists 6 types for 7 cells"});
  expect_error([] { read_vtk(write_file("size.vtk", replace(kCubeVtk, "CELLS 7 31", "CELLS 7 30"))); },
               {"size.vtk:", "overruns the CELLS size 30"});
  expect_error([] { read_vtk(write_file("head.vtk", "hello\n")); }, {"head.vtk:1:", "not a VTK legacy file"});
}

// By hand only (the project must not depend on shared data): gtest --gtest_also_run_disabled_tests.
TEST(SharedMeshes, DISABLED_SofaMeshes) {
  for (const char* path : {"/work/shared/data/sofa/liver2.msh", "/work/shared/data/sofa/liver.msh",
                           "/work/shared/data/sofa/cylinder.msh"}) {
    if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " is not here";
    TetMesh m = read_mesh(path);
    const std::size_t nodes = m.nodes.rows(), tets = m.tets.rows();
    std::string verdict = "valid";
    try {
      validate_mesh(m);
    } catch (const Error& e) {
      verdict = e.what();
    }
    const SurfaceMesh s = boundary_surface(m);
    std::printf("%s: %zu nodes, %zu tets, %ld boundary faces, %zu surface nodes, volume %.6g, divergence %.6g: %s\n",
                path, nodes, tets, static_cast<long>(s.tris.rows()), s.nodes.size(), total_volume(m),
                divergence_volume(m, s), verdict.c_str());
  }
}

TEST(MeshTest, TetQualityIsOneForTheRegularTetAndZeroForAFlatOne) {
  TetMesh m;
  m.nodes.resize(4, 3);
  m.nodes << 1, 1, 1, 1, -1, -1, -1, 1, -1, -1, -1, 1;  // regular, edge 2 sqrt(2)
  m.tets.resize(1, 4);
  m.tets << 0, 1, 2, 3;
  EXPECT_NEAR(tet_quality(m, 0), 1.0, 1e-12);
  m.nodes *= 1e-3;  // scale invariant
  EXPECT_NEAR(tet_quality(m, 0), 1.0, 1e-12);
  m.nodes.row(3) = (m.nodes.row(0) + m.nodes.row(1) + m.nodes.row(2)) / 3;  // flat
  EXPECT_NEAR(tet_quality(m, 0), 0.0, 1e-12);
}

}  // namespace
}  // namespace surgsim
