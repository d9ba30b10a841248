// Tests for common/liver/liver_setup.cpp: the precision a scene stores its tensors in, on both sides of the 1 GiB
// threshold, from the sizes alone (no tensor is computed or allocated).
#include "liver/liver_setup.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <vector>

using namespace surgsim::compliance;
using namespace surgsim::liver;

namespace surgsim {
namespace {

constexpr std::size_t kGiB = 1073741824;  // 2^30 bytes, written out

TEST(ScenePrecision, DoubleUpToTheThresholdFloatBeyond) {
  EXPECT_EQ(kFloatAboveMiB * 1048576, kGiB);  // the scenes' threshold is 1 GiB
  EXPECT_EQ(scene_precision(0), Precision::kDouble);
  EXPECT_EQ(scene_precision(kGiB), Precision::kDouble);  // at the threshold: still double
  EXPECT_EQ(scene_precision(kGiB + 1), Precision::kFloat);
  EXPECT_EQ(scene_precision(3 * kGiB), Precision::kFloat);
  // Another threshold, as a parameter: 1 MiB.
  EXPECT_EQ(scene_precision(1048576, 1), Precision::kDouble);
  EXPECT_EQ(scene_precision(1048577, 1), Precision::kFloat);
  EXPECT_EQ(scene_precision(kGiB, 2048), Precision::kDouble);
}

// The scene options on both sides of 1 GiB, sized by the layout (tensor_cache.h): the packed haptic half holds
// 9 S (S + 1) / 2 entries for S contact nodes, a dense block 9 R S for R rows; 8 bytes each in double.
TEST(ScenePrecision, SceneOptionsTurnFloatPastOneGiB) {
  const std::vector<RowSet> haptic = {RowSet{"haptic", {}}};  // packed: its size needs no row list
  EXPECT_EQ(estimate_tensor_bytes(5460, haptic, scene_precompute_options(5460, haptic)), 1073414160u);
  EXPECT_EQ(scene_precompute_options(5460, haptic).precision, Precision::kDouble);
  PrecomputeOptions as_double = scene_precompute_options(5461, haptic);
  EXPECT_EQ(as_double.precision, Precision::kFloat);
  as_double.precision = Precision::kDouble;
  EXPECT_EQ(estimate_tensor_bytes(5461, haptic, as_double), 1073807352u);

  // One dense row against many contact nodes: 72 bytes a contact node.
  const std::vector<RowSet> one_row = {RowSet{"visual", {0}}};
  EXPECT_EQ(scene_precompute_options(14913080, one_row).precision, Precision::kDouble);  // 1073741760 bytes
  EXPECT_EQ(scene_precompute_options(14913081, one_row).precision, Precision::kFloat);   // 1073741832 bytes
  EXPECT_EQ(scene_precompute_options(5460, haptic).symmetric_blocks, std::vector<std::string>{"haptic"});
}

}  // namespace
}  // namespace surgsim
