// Tests for common/mesh/format_obj.cpp: Wavefront .obj surfaces (relative indices, texture and normal indices
// skipped, polygons fanned) and every refusal naming FILE:LINE.
#include "mesh/mesh.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <string>

#include "core/error.h"
#include "mesh_test_util.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim {
namespace {

using namespace test;  // NOLINT(build/namespaces): the fixtures and helpers of mesh_test_util.h

TEST(ReadObj, RelativeIndicesTexturesNormalsAndBlanks) {
  const std::string path = write_file("square.obj",
                                      "# a square and a triangle\n"
                                      "o square\n"
                                      "v 0 0 0\n"
                                      "  v\t1 0 0\n"
                                      "v 1 1 0\r\n"
                                      "v 0 1 0.5\n"
                                      "vt 0 0\n"
                                      "vn 0 0 1\n"
                                      "f -4/1/1 -3/1/1 -2/1/1 -1/1/1\n"
                                      "f 1//1 2//1 4//1\n");
  const TriSurface s = read_obj(path);
  EXPECT_EQ(s.source, path);
  ASSERT_EQ(s.vertices.rows(), 4);
  EXPECT_EQ(s.vertices(1, 0), 1.0);
  EXPECT_EQ(s.vertices(3, 2), 0.5);
  ASSERT_EQ(s.tris.rows(), 3);
  Eigen::MatrixX3i expected(3, 3);
  expected << 0, 1, 2, 0, 2, 3, 0, 1, 3;
  EXPECT_TRUE(s.tris == expected);
}

TEST(ReadObj, ErrorsNameTheFileAndLine) {
  expect_error([] { read_obj(write_file("short.obj", "v 0 0 0\nv 1 2\n")); },
               {"short.obj:2: a vertex needs three numbers (v x y z)"});
  expect_error([] { read_obj(write_file("nan.obj", "v 0 0 0\nv 1 nan 0\n")); },
               {"nan.obj:2: non-finite vertex coordinate"});
  expect_error([] { read_obj(write_file("word.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 two 3\n")); },
               {"word.obj:4: a face index is not a number"});
  expect_error([] { read_obj(write_file("zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n")); },
               {"zero.obj:4: face index 0 is outside the 3 vertices defined so far"});
  expect_error([] { read_obj(write_file("back.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n")); },
               {"back.obj:4: face index -4 is outside the 3 vertices defined so far"});
  expect_error([] { read_obj(write_file("two.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n")); },
               {"two.obj:4: a face needs at least three vertices"});
  expect_error([] { read_obj(write_file("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n")); },
               {"points.obj: no faces (f lines): not a surface"});
  expect_error([] { read_obj(test_dir() + "/missing.obj"); }, {"missing.obj: cannot open the surface file"});
}

TEST(ReadObj, PolygonsAreFannedAndErrorsNameTheLine) {
  const std::string ok = ::testing::TempDir() + "/quad.obj";
  {
    std::FILE* f = std::fopen(ok.c_str(), "w");
    std::fprintf(f, "# a quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\n");
    std::fclose(f);
  }
  const TriSurface s = read_obj(ok);
  EXPECT_EQ(s.vertices.rows(), 4);
  EXPECT_EQ(s.tris.rows(), 2);
  const std::string bad = ::testing::TempDir() + "/bad.obj";
  {
    std::FILE* f = std::fopen(bad.c_str(), "w");
    std::fprintf(f, "v 0 0 0\nv 1 0 0\nf 1 2 7\n");
    std::fclose(f);
  }
  try {
    read_obj(bad);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.obj:3: face index 7"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace surgsim
