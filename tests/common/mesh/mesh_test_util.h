// Shared by the tests of common/mesh (mesh_test.cpp, validate_test.cpp, format_msh_test.cpp, format_vtk_test.cpp):
// the unit cube in every supported format, per-test file folders, and checks of errors and geometry.
#pragma once
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <initializer_list>
#include <sstream>
#include <string>

#include "core/error.h"
#include "mesh/mesh.h"

namespace surgsim::test {

// ---- Fixtures: a unit cube split into 5 tets (4 corner tets + a central one), in every supported format.
// Node order is the same everywhere: (0,0,0) (1,0,0) (1,1,0) (0,1,0) (0,0,1) (1,0,1) (1,1,1) (0,1,1).

inline mesh::TetMesh cube_mesh() {
  mesh::TetMesh m;
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
inline std::filesystem::path process_dir() {
  return std::filesystem::path(::testing::TempDir()) / ("surgsim_mesh_test_" + std::to_string(::getpid()));
}

class RemoveTestFiles : public ::testing::Environment {
 public:
  void TearDown() override { std::filesystem::remove_all(process_dir()); }
};
[[maybe_unused]] inline ::testing::Environment* const kRemoveTestFiles =
    ::testing::AddGlobalTestEnvironment(new RemoveTestFiles);

// A directory of its own per test.
inline std::string test_dir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::filesystem::path dir = process_dir() / (std::string(info->test_suite_name()) + "_" + info->name());
  std::filesystem::create_directories(dir);
  return dir.string();
}

inline std::string write_file(const std::string& name, const std::string& text) {
  const std::string path = test_dir() + "/" + name;
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

inline std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

inline std::string replace(std::string s, const std::string& from, const std::string& to) {
  const auto pos = s.find(from);
  EXPECT_NE(pos, std::string::npos) << "fixture edit: '" << from << "' not found";
  if (pos != std::string::npos) s.replace(pos, from.size(), to);
  return s;
}

// Runs f expecting a surgsim::core::Error whose message holds every part; returns the message.
inline std::string expect_error(const std::function<void()>& f, std::initializer_list<std::string> parts) {
  try {
    f();
  } catch (const core::Error& e) {
    const std::string msg = e.what();
    for (const std::string& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "missing '" << p << "' in: " << msg;
    return msg;
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected surgsim::core::Error, got another exception: " << e.what();
    return "";
  }
  ADD_FAILURE() << "expected surgsim::core::Error, nothing was thrown";
  return "";
}

inline void expect_same_geometry(const mesh::TetMesh& a, const mesh::TetMesh& b) {
  ASSERT_EQ(a.nodes.rows(), b.nodes.rows());
  ASSERT_EQ(a.tets.rows(), b.tets.rows());
  EXPECT_TRUE(a.nodes == b.nodes);
  EXPECT_TRUE(a.tets == b.tets);
  EXPECT_EQ(mesh::mesh_hash(a), mesh::mesh_hash(b));
}

inline double total_volume(const mesh::TetMesh& m) {
  double v = 0;
  for (int t = 0; t < m.tets.rows(); ++t) v += mesh::tet_volume(m, t);
  return v;
}

// n x n x n cubes of side h, 6 tets each (Kuhn/Freudenthal split, conforming); half the tets are inverted.
inline mesh::TetMesh grid_mesh(int n, double h) {
  mesh::TetMesh m;
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

}  // namespace surgsim::test
