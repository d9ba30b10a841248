// The liver's tensors with material regions (common/liver/liver_setup.cpp): the precomputed compliance is the
// inverse of the stiffness with each tet's own material, the cache key tells the regions apart, and a region that
// holds no tet is refused even when a cache would be found.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <filesystem>
#include <string>

#include "compliance/tensor_cache.h"
#include "fem/fem.h"
#include "liver/liver_setup.h"
#include "mesh/box_mesh.h"
#include "support/error_test_util.h"
#include "support/test_files.h"

using namespace surgsim::compliance;
using namespace surgsim::fem;
using namespace surgsim::liver;
using namespace surgsim::mesh;

namespace surgsim {
namespace {

// A 10 x 8 x 5 cm block clamped at x = 0 (a box around that face), a soft region beyond x = 5 cm.
struct Block {
  TetMesh mesh = make_box_mesh(5, 4, 3, Eigen::Vector3d(0.1, 0.08, 0.05));
  FixedRegion fixed;
  Material material{3000, 0.45};
  Block() {
    fixed.boxes.emplace_back(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1e-9, 1, 1));
    MaterialRegion soft;
    soft.name = "soft";
    soft.young_modulus = 750;
    soft.boxes.emplace_back(Eigen::Vector3d(0.05, -1, -1), Eigen::Vector3d(1, 1, 1));
    material.regions = {soft};
  }
};

TEST(LiverRegions, TensorsAreTheInverseOfTheStiffnessWithEachTetsMaterial) {
  const Block b;
  const std::string cache = test::fresh_test_dir("liver_regions_test_").string();
  const LiverTensorSetup setup = liver_tensor_setup(b.material, b.fixed, b.mesh, cache, "block.yaml");
  CacheOutcome outcome;
  const Tensors t = load_liver_tensors(setup, b.mesh, b.material, {"haptic"}, nullptr, &outcome, "block.yaml");
  EXPECT_TRUE(outcome.rebuilt);
  // The reference: K_ff^-1 by a dense LU of the region stiffness (MaterialRegions.* check that K against the
  // element stiffness summed with each tet's own material).
  const Eigen::MatrixXd k_ff = Eigen::MatrixXd(free_stiffness(assemble_stiffness(b.mesh, b.material), setup.fixed));
  const Eigen::MatrixXd c = k_ff.partialPivLu().inverse();
  const TensorBlock* haptic = t.find("haptic");
  ASSERT_NE(haptic, nullptr);
  const auto& free = setup.fixed.free_index();
  double worst = 0;
  for (int i : t.contact_nodes)
    for (int j : t.contact_nodes) {
      Eigen::Matrix3d ref;
      for (int r = 0; r < 3; ++r)
        for (int s = 0; s < 3; ++s)
          ref(r, s) = c(free[static_cast<std::size_t>(3 * i + r)], free[static_cast<std::size_t>(3 * j + s)]);
      const Eigen::Matrix3d g = haptic->block3(haptic->row_of_node[static_cast<std::size_t>(i)],
                                               t.column_of_node[static_cast<std::size_t>(j)]);
      worst = std::max(worst, (g - ref).norm());
    }
  EXPECT_LT(worst, 1e-9 * c.norm());
  // The homogeneous block's compliance is another: the comparison tells the materials apart.
  const Eigen::MatrixXd c1 = Eigen::MatrixXd(free_stiffness(assemble_stiffness(b.mesh, b.material.base()), setup.fixed))
                                 .partialPivLu()
                                 .inverse();
  EXPECT_GT((c1 - c).norm(), 0.1 * c.norm());
  ASSERT_TRUE(t.material.has_value());
  EXPECT_EQ(t.material->regions.size(), 1u);
}

TEST(LiverRegions, TheCacheKeyTellsTheRegionsApart) {
  const Block b;
  const std::string cache = test::fresh_test_dir("liver_regions_test_").string();
  const LiverTensorSetup with = liver_tensor_setup(b.material, b.fixed, b.mesh, cache, "block.yaml");
  const LiverTensorSetup without = liver_tensor_setup(b.material.base(), b.fixed, b.mesh, cache, "block.yaml");
  EXPECT_NE(with.key.material, without.key.material);
  EXPECT_NE(with.cache_path, without.cache_path);
  EXPECT_EQ(with.key.mesh, without.key.mesh);
  Material softer = b.material;
  softer.regions[0].young_modulus = 700;
  EXPECT_NE(liver_tensor_setup(softer, b.fixed, b.mesh, cache, "block.yaml").cache_path, with.cache_path);
}

TEST(LiverRegions, ARegionHoldingNoTetIsRefusedBeforeAnyCacheIsRead) {
  Block b;
  b.material.regions[0].boxes[0] = {Eigen::Vector3d(0.5, 0.5, 0.5), Eigen::Vector3d(1, 1, 1)};
  const std::string cache = test::fresh_test_dir("liver_regions_test_").string();
  const std::string what =
      test::error_of([&] { liver_tensor_setup(b.material, b.fixed, b.mesh, cache, "block.yaml"); });
  EXPECT_TRUE(test::contains(what, "block.yaml: material region 'soft' holds no element")) << what;
}

}  // namespace
}  // namespace surgsim
