// face_components, anchored_components, remove_elements and extract_component on hand-made meshes: tets joined by
// a face are one piece, by an edge or a node only two; compaction renumbers nodes in order and drops unused ones.
#include "cut/components.h"

#include <gtest/gtest.h>

#include <vector>

#include "core/error.h"
#include "mesh/box_mesh.h"
#include "mesh/mesh.h"

namespace surgsim::test {
namespace {

// Tet 0 (0 1 2 3); tet 1 shares the face (1 2 3); tet 2 (3 5 6 7) touches tet 1 at node 3 only; tet 3 (6 7 8 9)
// touches tet 2 along the edge (6 7).
mesh::TetMesh four_tets() {
  mesh::TetMesh m;
  m.nodes.resize(10, 3);
  m.nodes << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 9, 9, 9, 1, 1, 1, 2, 1, 1, 1, 2, 1, 3, 3, 3, 3, 3, 4;
  m.tets.resize(4, 4);
  m.tets << 0, 1, 2, 3, 1, 2, 3, 5, 3, 5, 6, 7, 6, 7, 8, 9;
  m.ids = {10, 11, 12, 13, 14, 15, 16, 17, 18, 19};
  return m;
}

TEST(CutComponents, OnlySharedFacesJoinTets) {
  const mesh::TetMesh m = four_tets();
  const cut::Components c = cut::face_components(m);
  EXPECT_EQ(c.count, 3);
  EXPECT_EQ(c.of_tet, (std::vector<int>{0, 0, 1, 2}));
  EXPECT_EQ(cut::anchored_components(m, c, {0}), (std::vector<bool>{true, false, false}));
  EXPECT_EQ(cut::anchored_components(m, c, {3}), (std::vector<bool>{true, true, false}));
  EXPECT_THROW(cut::anchored_components(m, c, {10}), core::Error);
}

TEST(CutComponents, BoxIsOnePiece) {
  const mesh::TetMesh m = mesh::make_box_mesh(3, 2, 2, {1, 1, 1});
  EXPECT_EQ(cut::face_components(m).count, 1);
}

TEST(CutComponents, RemovingElementsRenumbersAndDropsUnusedNodes) {
  const mesh::TetMesh m = four_tets();
  const cut::Compacted r = cut::remove_elements(m, {0, 2, 2});
  // Kept: tets 1 (1 2 3 5) and 3 (6 7 8 9); node 4 was never used, 0 only by tet 0.
  EXPECT_EQ(r.tet_map, (std::vector<int>{-1, 0, -1, 1}));
  EXPECT_EQ(r.node_map, (std::vector<int>{-1, 0, 1, 2, -1, 3, 4, 5, 6, 7}));
  ASSERT_EQ(r.mesh.tets.rows(), 2);
  EXPECT_EQ(r.mesh.tets.row(0), Eigen::RowVector4i(0, 1, 2, 3));
  EXPECT_EQ(r.mesh.tets.row(1), Eigen::RowVector4i(4, 5, 6, 7));
  ASSERT_EQ(r.mesh.nodes.rows(), 8);
  EXPECT_EQ(r.mesh.nodes.row(3), m.nodes.row(5));
  EXPECT_EQ(r.mesh.ids, (std::vector<std::int64_t>{11, 12, 13, 15, 16, 17, 18, 19}));
  EXPECT_THROW(cut::remove_elements(m, {4}), core::Error);
}

TEST(CutComponents, ExtractComponentKeepsItsTetsAlone) {
  const mesh::TetMesh m = four_tets();
  const cut::Components c = cut::face_components(m);
  const cut::Compacted piece = cut::extract_component(m, c, 0);
  EXPECT_EQ(piece.mesh.tets.rows(), 2);
  EXPECT_EQ(piece.mesh.nodes.rows(), 5);
  EXPECT_EQ(cut::face_components(piece.mesh).count, 1);
  EXPECT_THROW(cut::extract_component(m, c, 3), core::Error);
}

}  // namespace
}  // namespace surgsim::test
