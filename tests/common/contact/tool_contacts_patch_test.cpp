// What the hand feels from the liver's patch contact (smooth, frictionless or Coulomb), on a flat 20 x 20 x 4 cm slab
// of 1 cm cells fixed on its bottom face: ripple while sliding at constant depth (grid-aligned and at an irrational
// angle), the tangential force of a frictionless slide, Coulomb stick and slip, the force step at contact onset and at
// a grasp release, and a tool found again inside the organ after a reset. Each figure is printed (so the measured
// values can be quoted): ctest -R haptic_liver_patch_test -V.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <vector>

#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "compliance/precompute.h"
#include "mesh/box_mesh.h"
#include "contact/tool_contacts.h"
#include "support/layer_indentation.h"
#include "support/slab_util.h"

using namespace surgsim::mesh;
using namespace surgsim::tool;
using namespace surgsim::compliance;
using namespace surgsim::contact;

namespace surgsim {
namespace {

constexpr double kTop = 0.04;  // m, top face of the slab
constexpr double kDt = 1e-3;   // s, 1 kHz

class LiverPatchTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    slab_ = new test::Slab(20, 20, 4, {0.2, 0.2, 0.04});
    mesh_ = &slab_->mesh;
    surface_ = &slab_->surface;
    tensors_ = &slab_->tensors;
  }
  static void TearDownTestSuite() { delete slab_; }
  void SetUp() override {
    spec_.shaft_points = 1;
    spec_.force_limit = 100.0;
    spec_.contact_capacity = 64;
  }
  static ToolGeometry at(const Eigen::Vector3d& tip) { return test::vertical_tool(tip); }
  static ContactTick step(ToolContacts& c, const Eigen::Vector3d& tip, double jaw = 0.5) {
    ContactTick t;
    c.step(at(tip), jaw, t, kDt);
    return t;
  }

  struct Slide {
    double ripple = 0;      // peak-to-peak of the detrended normal force / mean
    double tangential = 0;  // largest |F_t| / F_n
    double mean = 0;        // N
  };
  // Press to `depth` at `start`, settle, then slide `length` along the unit `dir` in 0.2 mm ticks at constant depth.
  Slide slide(ContactModel model, const Eigen::Vector3d& start, const Eigen::Vector3d& dir, double depth,
              double length) {
    ToolSpec spec = spec_;
    spec.contact_model = model;
    ToolContacts c(*mesh_, *surface_, *tensors_, spec);
    const Eigen::Vector3d down(0, 0, -1);
    step(c, start + Eigen::Vector3d(0, 0, kTop + 0.002));
    for (int k = 0; k <= 100; ++k) step(c, start + Eigen::Vector3d(0, 0, kTop - depth * std::min(1.0, k / 50.0)));
    std::vector<double> s, fn;
    Slide out;
    const int n = static_cast<int>(length / 0.0002);
    for (int k = 0; k <= n; ++k) {
      const Eigen::Vector3d tip = start + k * 0.0002 * dir + Eigen::Vector3d(0, 0, kTop - depth);
      const ContactTick t = step(c, tip);
      EXPECT_EQ(t.points_in_contact, 1) << k;
      s.push_back(k * 0.0002);
      fn.push_back(t.force.z());
      out.tangential = std::max(out.tangential, t.force.head<2>().norm() / t.force.z());
    }
    double sum = 0;
    for (double f : fn) sum += f;
    out.mean = sum / static_cast<double>(fn.size());
    out.ripple = test::detrended_ripple(s, fn);
    return out;
  }

  static test::Slab* slab_;
  static const TetMesh* mesh_;
  static const SurfaceMesh* surface_;
  static const Tensors* tensors_;
  ToolSpec spec_;
};
test::Slab* LiverPatchTest::slab_ = nullptr;
const TetMesh* LiverPatchTest::mesh_ = nullptr;
const SurfaceMesh* LiverPatchTest::surface_ = nullptr;
const Tensors* LiverPatchTest::tensors_ = nullptr;

// Part 2 and 3: at constant depth the normal force does not depend on where the tip is relative to the mesh (ripple
// <= 5 % of the mean, trend removed), along a grid line and at an irrational angle; frictionless: |F_t| <= 2 % F_n.
TEST_F(LiverPatchTest, SlidingAtConstantDepthIsSmoothAndFrictionless) {
  const double golden = 0.5 * (1 + std::sqrt(5.0));
  const Eigen::Vector3d along_x(1, 0, 0);
  const Eigen::Vector3d oblique = Eigen::Vector3d(golden, 1, 0).normalized();  // 31.7 degrees to the grid
  struct Path {
    const char* name;
    Eigen::Vector3d start, dir;
  };
  for (const Path& path :
       {Path{"grid-aligned", {0.0731, 0.0977, 0}, along_x}, Path{"irrational angle", {0.0731, 0.0777, 0}, oblique}}) {
    for (double depth : {0.001, 0.003}) {
      const Slide patch = slide(ContactModel::kPatch, path.start, path.dir, depth, 0.05);
      const Slide triangle = slide(ContactModel::kTriangle, path.start, path.dir, depth, 0.05);
      std::cout << "[ripple] " << path.name << ", depth " << depth * 1e3 << " mm: patch ripple " << 100 * patch.ripple
                << " %, tangential max " << 100 * patch.tangential << " % (mean " << patch.mean
                << " N); triangle model ripple " << 100 * triangle.ripple << " %, tangential max "
                << 100 * triangle.tangential << " % (mean " << triangle.mean << " N)\n";
      RecordProperty(std::string("ripple_patch_") + (path.dir.y() == 0 ? "grid_" : "oblique_") +
                         std::to_string(static_cast<int>(depth * 1e3)) + "mm_pct",
                     std::to_string(100 * patch.ripple));
      EXPECT_LE(patch.ripple, 0.05) << path.name << " depth " << depth;
      EXPECT_LE(patch.tangential, 0.02) << path.name << " depth " << depth;
    }
  }
}

// The footprint contact is a flat punch of the tip's own radius (5 mm), whatever the mesh: pressed 1 mm into the
// bottom-fixed 4 cm slab, its force matches the bonded-layer solution (Hayes et al. 1972, tests/support/
// layer_indentation.h, an independent Fredholm solve) on this slab's 1 cm cells (coarser than the tip) and on 5 mm
// cells, and the two meshes agree. The earlier node patch at the same radius misses by 20-40 % and depends on where
// the tip sits (no node within 5 mm at some positions).
TEST_F(LiverPatchTest, FlatPunchMatchesTheBondedLayerOnAnyMesh) {
  const double a = 0.005, depth = 0.001;
  const double ref = test::hayes_force(a, 0.04, 3000.0, 0.45, depth);
  const auto punch = [&](const test::Slab& slab, const Eigen::Vector2d& corner, double cell, TipModel tip) {
    ToolSpec spec = spec_;
    spec.tip_radius = a;
    spec.tip_model = tip;
    double sum = 0;
    for (int k = 0; k < 5; ++k) {  // positions across a cell, off the node lines
      ToolContacts c(slab.mesh, slab.surface, slab.tensors, spec);
      const Eigen::Vector2d xy = corner + cell * Eigen::Vector2d(0.2 * k + 0.1, 0.3);
      double f = 0;
      for (int t = 0; t <= 60; ++t)
        f = step(c, Eigen::Vector3d(xy.x(), xy.y(), kTop + depth - std::min(2 * depth, t * 2 * depth / 40))).force.z();
      sum += f / 5;
    }
    return sum;
  };
  const test::Slab fine(20, 20, 8, {0.1, 0.1, 0.04});
  const double coarse = punch(*slab_, {0.1, 0.1}, 0.01, TipModel::kFootprint);
  const double finer = punch(fine, {0.05, 0.05}, 0.005, TipModel::kFootprint);
  const double nodes = punch(*slab_, {0.1, 0.1}, 0.01, TipModel::kNodes);
  std::cout << "[punch] Hayes " << ref << " N; footprint 1 cm cells " << coarse << " N (" << 100 * (coarse / ref - 1)
            << " %), 5 mm cells " << finer << " N (" << 100 * (finer / ref - 1) << " %); node patch 1 cm cells "
            << nodes << " N (" << 100 * (nodes / ref - 1) << " %)\n";
  EXPECT_NEAR(coarse / ref, 1.0, 0.07);
  EXPECT_NEAR(finer / ref, 1.0, 0.06);
  EXPECT_NEAR(coarse / finer, 1.0, 0.05);
  EXPECT_GT(std::abs(nodes / ref - 1), 0.1);
}

// Part 3: with tool.friction = mu the tip sticks (|F_t| < mu F_n, the tissue dragged along) for a small tangential
// move, and slides with |F_t| = mu F_n (opposing the motion) once it would exceed that.
TEST_F(LiverPatchTest, CoulombFrictionSticksThenSlips) {
  spec_.friction = 0.3;
  ToolContacts c(*mesh_, *surface_, *tensors_, spec_);
  const Eigen::Vector3d start(0.0731, 0.0977, kTop);
  step(c, start + Eigen::Vector3d(0, 0, 0.002));
  for (int k = 0; k <= 60; ++k) step(c, start - Eigen::Vector3d(0, 0, 0.003 * std::min(1.0, k / 30.0)));
  const Eigen::Vector3d stuck = c.point(0).stick_anchor;
  // A 0.2 mm move: sticks.
  ContactTick t;
  for (int k = 1; k <= 4; ++k) t = step(c, start + Eigen::Vector3d(0.00005 * k, 0, -0.003));
  double ft = t.force.head<2>().norm(), fn = t.force.z();
  std::cout << "[friction] mu 0.3, 0.2 mm move: |F_t| / F_n = " << ft / fn << ", slipping " << c.point(0).slipping
            << "\n";
  EXPECT_FALSE(c.point(0).slipping);
  EXPECT_LT(ft, 0.3 * fn);
  EXPECT_GT(ft, 0.01 * fn) << "a sticking tip drags the tissue";
  EXPECT_LT(t.force.x(), 0.0) << "the drag opposes the motion";
  EXPECT_NEAR((c.point(0).stick_anchor - stuck).norm(), 0.0, 1e-15);
  // Keep going 20 mm: slides, |F_t| = mu F_n.
  double worst = 0;
  for (int k = 5; k <= 400; ++k) {
    t = step(c, start + Eigen::Vector3d(0.00005 * k, 0, -0.003));
    if (k > 200) worst = std::max(worst, std::abs(t.force.head<2>().norm() / t.force.z() - 0.3));
  }
  ft = t.force.head<2>().norm();
  fn = t.force.z();
  std::cout << "[friction] mu 0.3, sliding: |F_t| / F_n = " << ft / fn << " (largest deviation from mu " << worst
            << ")\n";
  EXPECT_TRUE(c.point(0).slipping);
  EXPECT_LT(t.force.x(), 0.0);
  EXPECT_LT(worst, 0.02 * 0.3);
  EXPECT_GT((c.point(0).stick_anchor - stuck).norm(), 0.01) << "the stick point followed the slide";
}

// Part 4: the largest one-tick change of the force at contact onset (0.1 m/s at 1 kHz) and at a grasp release is
// <= 5 % of the force held afterwards (onset) or before (release); a fast stab no longer jumps to its full force.
TEST_F(LiverPatchTest, OnsetAndReleaseAreContinuous) {
  const Eigen::Vector3d start(0.0731, 0.0977, kTop + 0.003);
  // Approach at 0.1 m/s to 3 mm deep, hold 100 ms.
  {
    ToolContacts c(*mesh_, *surface_, *tensors_, spec_);
    double prev = 0, step_max = 0, held = 0;
    for (int k = 0; k <= 160; ++k) {
      const double z = std::max(-0.006, -1e-4 * k);
      held = step(c, start + Eigen::Vector3d(0, 0, z)).force.norm();
      step_max = std::max(step_max, std::abs(held - prev));
      prev = held;
    }
    std::cout << "[onset] 0.1 m/s to 3 mm: largest one-tick step " << step_max << " N = " << 100 * step_max / held
              << " % of the held " << held << " N\n";
    EXPECT_LE(step_max, 0.05 * held);
  }
  // A fast stab (5 mm deep in one tick): blended in over the onset ramp.
  {
    ToolContacts c(*mesh_, *surface_, *tensors_, spec_);
    step(c, start);
    double prev = 0, step_max = 0, held = 0;
    for (int k = 0; k < 100; ++k) {
      held = step(c, start + Eigen::Vector3d(0, 0, -0.008)).force.norm();
      step_max = std::max(step_max, std::abs(held - prev));
      prev = held;
    }
    std::cout << "[onset] 5 mm stab in one tick: largest one-tick step " << 100 * step_max / held << " % of the held "
              << held << " N\n";
    EXPECT_LE(step_max, 0.1 * held);
  }
  // A grasp pulled 3 mm above the rest surface, then released.
  {
    ToolContacts c(*mesh_, *surface_, *tensors_, spec_);
    for (int k = 0; k <= 60; ++k) step(c, start + Eigen::Vector3d(0, 0, std::max(-0.006, -1e-4 * k)));
    for (int k = 0; k < 10; ++k) step(c, start + Eigen::Vector3d(0, 0, -0.006), 0.0);  // jaw closed
    ContactTick t;
    for (int k = 0; k <= 60; ++k) t = step(c, start + Eigen::Vector3d(0, 0, -0.006 + 1e-4 * k), 0.0);
    ASSERT_TRUE(t.grasp);
    ASSERT_LT(t.force.z(), 0.0) << "the tissue pulls back";
    const double held = t.force.norm();
    double prev = held, step_max = 0, last = held;
    for (int k = 0; k < 100; ++k) {
      t = step(c, start, 0.5);  // jaw open
      step_max = std::max(step_max, std::abs(t.force.norm() - prev));
      prev = last = t.force.norm();
    }
    std::cout << "[release] grasp holding " << held << " N: largest one-tick step " << 100 * step_max / held
              << " % of it\n";
    EXPECT_FALSE(t.grasp);
    EXPECT_EQ(last, 0.0) << "released within the fade";
    EXPECT_LE(step_max, 0.05 * held);
  }
}

// Part 6: after a reset (input lost) or a non-finite pose, a tool already inside the organ is found again from the
// rest surface and the force is back in one tick.
TEST_F(LiverPatchTest, ResumesInsideInOneTick) {
  ToolContacts c(*mesh_, *surface_, *tensors_, spec_);
  const Eigen::Vector3d start(0.0731, 0.0977, kTop + 0.002);
  ContactTick t;
  for (int k = 0; k <= 120; ++k) t = step(c, start + Eigen::Vector3d(0, 0, std::max(-0.008, -1e-4 * k)));
  const Eigen::Vector3d inside = start + Eigen::Vector3d(0, 0, -0.008);
  const double before = t.force.z();
  ASSERT_GT(before, 0.0);
  c.reset();  // input lost
  t = step(c, inside);
  std::cout << "[resume] after a reset: " << t.force.z() << " N in the first tick (before: " << before << " N)\n";
  EXPECT_NEAR(t.force.z(), before, 1e-9 * before);
  // A non-finite pose, then the same good pose.
  ToolGeometry bad = at(inside);
  bad.points[0].x() = std::numeric_limits<double>::quiet_NaN();
  c.step(bad, 0.5, t, kDt);
  EXPECT_TRUE(t.nonfinite);
  t = step(c, inside);
  EXPECT_NEAR(t.force.z(), before, 1e-9 * before);
}

}  // namespace
}  // namespace surgsim
