// Tests for common/mesh/format_vtk.cpp: VTK legacy written and read back exactly, with a node vector field, and
// malformed files refused with FILE:LINE.
#include "mesh/mesh.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <string>

#include "core/error.h"
#include "mesh_test_util.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim {
namespace {

using namespace test;  // NOLINT(build/namespaces): the fixtures and helpers of mesh_test_util.h

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

TEST(WriteMesh, UnwritablePathIsAnError) {
  expect_error([] { write_vtk("/nonexistent-dir/x.vtk", cube_mesh()); }, {"/nonexistent-dir/x.vtk", "cannot open"});
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

}  // namespace
}  // namespace surgsim
