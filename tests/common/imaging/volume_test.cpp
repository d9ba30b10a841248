// Tests for common/imaging/volume.cpp: label selection and its refusals, clean-up, the majority filter, the
// voxelization of a surface and the seeded noise.
#include "imaging/volume.h"

#include <gtest/gtest.h>

#include <string>

#include "support/error_test_util.h"
#include "core/error.h"

using namespace surgsim::imaging;

namespace surgsim {
namespace {

using test::error_of;
using test::contains;

LabelVolume blank(int nx, int ny, int nz, const std::string& source = "test.nrrd") {
  LabelVolume v;
  v.grid.size = Eigen::Vector3i(nx, ny, nz);
  v.grid.spacing = Eigen::Vector3d::Constant(0.001);
  v.labels.assign(static_cast<std::size_t>(nx) * ny * nz, 0);
  v.source = source;
  return v;
}

void fill_box(LabelVolume& v, Eigen::Vector3i lo, Eigen::Vector3i hi, std::int32_t label) {
  for (int k = lo.z(); k <= hi.z(); ++k)
    for (int j = lo.y(); j <= hi.y(); ++j)
      for (int i = lo.x(); i <= hi.x(); ++i) v.labels[static_cast<std::size_t>(v.grid.index(i, j, k))] = label;
}

TEST(Volume, SelectsTheOnlyLabelOrTheOneAskedFor) {
  LabelVolume v = blank(8, 8, 8);
  fill_box(v, {1, 1, 1}, {3, 3, 3}, 5);
  VoxelMask m = select_label(v);
  EXPECT_EQ(m.label, 5);
  EXPECT_EQ(m.count(), 27);
  fill_box(v, {5, 5, 5}, {6, 6, 6}, 9);
  m = select_label(v, 9);
  EXPECT_EQ(m.count(), 8);
  EXPECT_TRUE(m.at(5, 6, 5));
  EXPECT_FALSE(m.at(1, 1, 1));
  const auto counts = label_counts(v);
  ASSERT_EQ(counts.size(), 3u);
  EXPECT_EQ(counts[1].first, 5);
  EXPECT_EQ(counts[1].second, 27);
}

TEST(Volume, RefusesBadSelectionsNamingTheFile) {
  // Empty: no foreground.
  LabelVolume empty = blank(4, 4, 4, "scans/empty.nrrd");
  std::string e = error_of([&] { select_label(empty); });
  EXPECT_TRUE(contains(e, "scans/empty.nrrd") && contains(e, "no foreground")) << e;
  // All foreground.
  LabelVolume full = blank(4, 4, 4, "scans/full.nrrd");
  fill_box(full, {0, 0, 0}, {3, 3, 3}, 1);
  e = error_of([&] { select_label(full); });
  EXPECT_TRUE(contains(e, "scans/full.nrrd") && contains(e, "every voxel is foreground")) << e;
  e = error_of([&] { select_label(full, 1); });
  EXPECT_TRUE(contains(e, "scans/full.nrrd")) << e;
  // A label that does not exist: the message lists those present.
  LabelVolume two = blank(6, 6, 6, "scans/two.nrrd");
  fill_box(two, {0, 0, 0}, {1, 1, 1}, 3);
  fill_box(two, {3, 3, 3}, {4, 4, 4}, 7);
  e = error_of([&] { select_label(two, 5); });
  EXPECT_TRUE(contains(e, "scans/two.nrrd") && contains(e, "label 5 not present") && contains(e, "0 (200 voxels)") &&
              contains(e, "3 (8 voxels)") && contains(e, "7 (8 voxels)"))
      << e;
  // Several labels and none chosen.
  e = error_of([&] { select_label(two); });
  EXPECT_TRUE(contains(e, "scans/two.nrrd") && contains(e, "--label")) << e;
  // The background is not an organ.
  e = error_of([&] { select_label(two, 0); });
  EXPECT_TRUE(contains(e, "background")) << e;
  // Sizes that do not match the labels.
  LabelVolume broken = blank(4, 4, 4, "scans/broken.nrrd");
  broken.labels.pop_back();
  e = error_of([&] { select_label(broken); });
  EXPECT_TRUE(contains(e, "scans/broken.nrrd")) << e;
}

TEST(Volume, CleanupKeepsTheLargestPieceAndFillsCavities) {
  LabelVolume v = blank(12, 12, 12);
  fill_box(v, {1, 1, 1}, {6, 6, 6}, 1);    // 216 voxels, with a cavity:
  fill_box(v, {3, 3, 3}, {4, 4, 4}, 0);    // 8 enclosed background voxels
  fill_box(v, {9, 9, 9}, {10, 10, 10}, 1);  // a stray 8-voxel piece
  v.labels[static_cast<std::size_t>(v.grid.index(7, 7, 6))] = 1;  // touches the big piece along an edge only
  VoxelMask m = select_label(v);
  const MaskCleanup c = clean_mask(m);
  EXPECT_EQ(c.components, 3);
  EXPECT_EQ(c.removed_voxels, 9);
  EXPECT_EQ(c.cavities, 1);
  EXPECT_EQ(c.filled_voxels, 8);
  EXPECT_EQ(m.count(), 216);
  EXPECT_TRUE(m.at(3, 3, 3));
  EXPECT_FALSE(m.at(9, 9, 9));
  EXPECT_FALSE(m.at(7, 7, 6));
}

TEST(Volume, MajorityFilterRemovesSpecklesAndPinholes) {
  LabelVolume v = blank(12, 12, 12);
  fill_box(v, {2, 2, 2}, {9, 9, 9}, 1);
  v.labels[static_cast<std::size_t>(v.grid.index(5, 5, 9))] = 0;  // a pinhole in the top face
  v.labels[static_cast<std::size_t>(v.grid.index(0, 11, 0))] = 1;  // a speckle in a corner
  VoxelMask m = select_label(v);
  const std::int64_t changed = majority_filter(m, 1);
  EXPECT_TRUE(m.at(5, 5, 9));
  EXPECT_FALSE(m.at(0, 11, 0));
  EXPECT_TRUE(m.at(5, 5, 5));
  EXPECT_FALSE(m.at(2, 2, 2));  // a box's corner voxels have 8 of 27 inside: rounded off
  EXPECT_GE(changed, 2 + 8);
}

// A closed box surface (outward) for voxelize.
void box_surface(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, Eigen::MatrixX3d& v, Eigen::MatrixX3i& f) {
  v.resize(8, 3);
  for (int c = 0; c < 8; ++c) v.row(c) << (c & 1 ? hi.x() : lo.x()), (c & 2 ? hi.y() : lo.y()), (c & 4 ? hi.z() : lo.z());
  f.resize(12, 3);
  f << 0, 2, 1, 1, 2, 3,  // z = lo
      4, 5, 6, 5, 7, 6,   // z = hi
      0, 1, 4, 1, 5, 4,   // y = lo
      2, 6, 3, 3, 6, 7,   // y = hi
      0, 4, 2, 2, 4, 6,   // x = lo
      1, 3, 5, 3, 7, 5;   // x = hi
}

TEST(Volume, VoxelizesAClosedSurface) {
  Eigen::MatrixX3d v;
  Eigen::MatrixX3i f;
  box_surface(Eigen::Vector3d(0.0, 0.0, 0.0), Eigen::Vector3d(0.0203, 0.0101, 0.0152), v, f);
  const LabelVolume vol = voxelize(v, f, 0.001, 2, 4);
  VoxelMask m = select_label(vol);
  EXPECT_EQ(m.label, 4);
  // Voxel centres inside a 20.3 x 10.1 x 15.2 mm box on a 1 mm grid centred on it: 20 x 10 x 15 or one more per
  // axis, depending on where the centres fall; the volume is right within a voxel layer.
  const double volume = static_cast<double>(m.count()) * 1e-9;
  EXPECT_NEAR(volume, 0.0203 * 0.0101 * 0.0152, 0.0203 * 0.0101 * 0.0152 * 0.25);
  // The margin: two empty layers on every side.
  for (int i = 0; i < vol.grid.size.x(); ++i) EXPECT_FALSE(m.at(i, 1, 1));
}

TEST(Volume, NoiseIsSeededAndStaysAtTheBoundary) {
  LabelVolume v = blank(20, 20, 20);
  fill_box(v, {5, 5, 5}, {14, 14, 14}, 1);
  LabelVolume a = v, b = v, c = v;
  add_label_noise(a, 0.3, 5, 7);
  add_label_noise(b, 0.3, 5, 7);
  add_label_noise(c, 0.3, 5, 8);
  EXPECT_EQ(a.labels, b.labels);
  EXPECT_NE(a.labels, c.labels);
  int flipped_inside = 0, near = 0;
  for (int k = 0; k < 20; ++k)
    for (int j = 0; j < 20; ++j)
      for (int i = 0; i < 20; ++i) {
        const auto idx = static_cast<std::size_t>(v.grid.index(i, j, k));
        if (a.labels[idx] == v.labels[idx]) continue;
        const bool deep = i >= 7 && i <= 12 && j >= 7 && j <= 12 && k >= 7 && k <= 12;
        if (deep) ++flipped_inside;
        const bool shell = i >= 4 && i <= 15 && j >= 4 && j <= 15 && k >= 4 && k <= 15;
        if (shell) ++near;
      }
  EXPECT_EQ(flipped_inside, 0);
  EXPECT_GT(near, 100);
}

}  // namespace
}  // namespace surgsim
