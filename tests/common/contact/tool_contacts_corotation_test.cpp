// The liver's corotational contacts (ToolContacts with LiverDeformation::kCorotational) on a 20 x 20 x 4
// cm slab fixed on its bottom face: a shallow press feels as the linear one, a grasp dragged far sideways turns its
// patch and the contact nodes' rotations follow it, and the tick allocates nothing once warm (the background
// refresh runs between ticks here, as LiverOrgan's thread does beside them). ctest -R haptic_liver_corotation -V.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <iostream>
#include <memory>
#include <vector>

#include "contact/tool_contacts.h"
#include "support/alloc_counter.h"
#include "support/slab_util.h"

using namespace surgsim::tool;
using namespace surgsim::compliance;
using namespace surgsim::contact;

namespace surgsim {
namespace {

constexpr double kTop = 0.04;  // m, top face of the slab

class LiverCorotationTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { slab_ = new test::Slab(14, 14, 4, {0.2, 0.2, 0.04}); }
  static void TearDownTestSuite() { delete slab_; }
  void SetUp() override {
    spec_.shaft_points = 1;
    spec_.force_limit = 1000.0;
    spec_.contact_capacity = 64;
  }
  std::unique_ptr<ToolContacts> make(LiverDeformation d) const {
    return std::make_unique<ToolContacts>(slab_->mesh, slab_->surface, slab_->tensors, std::vector<ToolSpec>{spec_},
                                          nullptr, d);
  }
  static ContactTick step(ToolContacts& c, const Eigen::Vector3d& tip, double jaw = 0.5) {
    ContactTick t;
    c.step(test::vertical_tool(tip), jaw, t);
    c.refresh_rotations();
    return t;
  }
  static test::Slab* slab_;
  ToolSpec spec_;
};
test::Slab* LiverCorotationTest::slab_ = nullptr;

TEST_F(LiverCorotationTest, ShallowPressFeelsAsTheLinearOne) {
  auto lin_ptr = make(LiverDeformation::kLinear);
  auto cor_ptr = make(LiverDeformation::kCorotational);
  ToolContacts& lin = *lin_ptr;
  ToolContacts& cor = *cor_ptr;
  const Eigen::Vector3d at(0.1003, 0.0997, kTop + 0.001);
  ContactTick tl, tc;
  for (int k = 0; k <= 40; ++k) {  // 0.5 mm deep in 40 ticks
    const Eigen::Vector3d tip = at - Eigen::Vector3d(0, 0, 0.0015 * k / 40.0);
    tl = step(lin, tip);
    tc = step(cor, tip);
  }
  ASSERT_GT(tl.force.norm(), 0);
  const double diff = (tc.force - tl.force).norm() / tl.force.norm();
  std::cout << "0.5 mm press: linear " << tl.force.transpose() << " N, corotational " << tc.force.transpose()
            << " N, relative difference " << diff << "\n";
  EXPECT_LT(diff, 0.01);
}

TEST_F(LiverCorotationTest, GraspDraggedSidewaysTurnsItsPatchAndTheRotationsFollow) {
  auto lin_ptr = make(LiverDeformation::kLinear);
  auto cor_ptr = make(LiverDeformation::kCorotational);
  ToolContacts& lin = *lin_ptr;
  ToolContacts& cor = *cor_ptr;
  const Eigen::Vector3d at(0.1, 0.1, kTop - 0.002);
  for (ToolContacts* c : {&lin, &cor}) {
    step(*c, at + Eigen::Vector3d(0, 0, 0.004));
    step(*c, at);
    step(*c, at, 0.0);  // jaw closed: grasp
  }
  ContactTick tl, tc;
  for (int k = 1; k <= 200; ++k) {  // drag 3 cm sideways and 2 cm up
    const Eigen::Vector3d tip = at + Eigen::Vector3d(0.03, 0, 0.02) * (k / 200.0);
    tl = step(lin, tip, 0.0);
    tc = step(cor, tip, 0.0);
  }
  ASSERT_TRUE(tc.grasp);
  ASSERT_GT(cor.solution().count, 0);
  // The contact nodes' rotations: about y (the drag is along x, lifting), by a few degrees or more.
  double largest = 0;
  for (int l = 0; l < cor.solution().count; ++l) {
    const Eigen::AngleAxisd aa(cor.rotations()->rotation(cor.solution().nodes[static_cast<std::size_t>(l)]));
    largest = std::max(largest, aa.angle());
  }
  std::cout << "grasp dragged 3 cm sideways, 2 cm up: largest contact-node rotation " << largest * 180 / 3.14159265
            << " degrees; force linear " << tl.force.transpose() << " N, corotational " << tc.force.transpose()
            << " N\n";
  EXPECT_GT(largest, 2 * 3.14159265 / 180);
  EXPECT_TRUE(tc.force.allFinite());
  EXPECT_GT((tc.force - tl.force).norm(), 1e-3 * tl.force.norm());  // the warping acts
}

TEST_F(LiverCorotationTest, TickAllocatesNothingOnceWarm) {
  auto c_ptr = make(LiverDeformation::kCorotational);
  ToolContacts& c = *c_ptr;
  const Eigen::Vector3d at(0.1, 0.1, kTop);
  step(c, at + Eigen::Vector3d(0, 0, 0.003));
  step(c, at - Eigen::Vector3d(0, 0, 0.003));
  long allocations = 0;
  for (int k = 0; k < 200; ++k) {
    const Eigen::Vector3d tip = at + Eigen::Vector3d(0.01 * std::sin(0.03 * k), 0, -0.004 - 0.003 * std::sin(0.05 * k));
    ContactTick t;
    {
      test::AllocationCounter counter;
      c.step(test::vertical_tool(tip), k % 60 < 30 ? 0.5 : 0.0, t);
      allocations += counter.count();
    }
    if (k % 10 == 0) {
      test::AllocationCounter counter;
      c.refresh_rotations();
      allocations += counter.count();
    }
    ASSERT_TRUE(t.force.allFinite());
  }
  EXPECT_EQ(allocations, 0);
}

}  // namespace
}  // namespace surgsim
