// Tests for common/mesh/format_msh.cpp: Gmsh .msh v1, v2, v4 read (CRLF, truncation, every prefix, malformed
// content, FILE:LINE in messages) and v2.2 written back with its ids.
#include "mesh/mesh.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "core/error.h"
#include "mesh_test_util.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim {
namespace {

using namespace test;  // NOLINT(build/namespaces): the fixtures and helpers of mesh_test_util.h

TEST(ReadMesh, CrlfLineEndsAndNoFinalNewline) {
  std::string text = kCubeV1;
  std::string crlf;
  for (char c : text) crlf += c == '\n' ? std::string("\r\n") : std::string(1, c);
  crlf.resize(crlf.size() - 2);  // "...$ENDELM" without a final line end
  expect_same_geometry(read_msh(write_file("crlf.msh", crlf)), cube_mesh());
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

}  // namespace
}  // namespace surgsim
