// The shipped liver (config/liver.yaml, tensors from the cache) under a straight press and an input loss: the force
// grows monotonically with depth until the device limit (it fell from 3.36 to 1.43 N in one tick at 33 mm when the
// contact re-anchored on another face), the onset at 0.1 m/s and 1 kHz has no step, and a tool still inside when
// input returns gets its force back in the first tick. A model swapped in between two ticks.
#include "organs/liver_organ.h"

#include <gtest/gtest.h>

#include "support/alloc_counter.h"
#include "mesher/scene_mesh.h"

#include <cmath>
#include <iostream>

using namespace surgsim::tool;
using namespace surgsim::contact;
using namespace surgsim::scene;

namespace surgsim {
namespace {

class LiverOrganTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = new Scene(load_scene(resolve_scene_path("liver")));
    organ_ = new LiverOrgan(*scene_, SURGSIM_TEST_CACHE_DIR, nullptr);
  }
  static void TearDownTestSuite() {
    delete organ_;
    delete scene_;
  }
  static Scene* scene_;
  static LiverOrgan* organ_;
};
Scene* LiverOrganTest::scene_ = nullptr;
LiverOrgan* LiverOrganTest::organ_ = nullptr;

// Straight down from 1 cm above the top at 0.1 m/s and 1 kHz, the shipped tool (4 shaft points, the law, 8 N).
TEST_F(LiverOrganTest, StraightPressGrowsMonotonicallyToTheDeviceLimit) {
  LiverOrgan& organ = *organ_;
  ContactTick reset_tick;
  organ.step(nullptr, 0.5, 1e-3, reset_tick);
  const double dt = 1e-3, v = 0.1;
  Pose5 p;
  p.jaw = 0.5;
  double prev = 0, step_max = 0, at_limit = -1;
  int first_contact = -1, saturated_ticks = 0;
  for (int k = 0; k < 1000 && saturated_ticks < 50; ++k) {
    p.insertion = 0.15 + v * dt * k;
    const ToolGeometry g = tool_geometry(scene_->tools[0], p);
    ContactTick t;
    organ.step(&g, p.jaw, dt, t);
    const double f = t.device_force.norm();
    if (first_contact < 0 && t.points_in_contact > 0) first_contact = k;
    ASSERT_GE(f, prev - 1e-12) << "the force fell at tick " << k << ", tip z " << g.tip.z();
    if (first_contact >= 0 && !t.saturated) step_max = std::max(step_max, f - prev);
    if (t.saturated) {
      if (at_limit < 0) at_limit = 0.04 - g.tip.z();
      ++saturated_ticks;
    }
    prev = f;
  }
  std::cout << "[press] shipped liver: monotonic to the 8 N limit (reached about " << at_limit * 1e3
            << " mm below z = 0.04); largest one-tick increase " << step_max << " N\n";
  EXPECT_GT(saturated_ticks, 0) << "the press reaches the device limit";
  EXPECT_GE(first_contact, 0);
}

// Input lost with the tool 2 cm inside (LiverOrgan::step(nullptr) drops every contact), then back at the same pose.
TEST_F(LiverOrganTest, InputReturningInsideGetsTheForceBackInOneTick) {
  LiverOrgan& organ = *organ_;
  ContactTick t;
  organ.step(nullptr, 0.5, 1e-3, t);
  Pose5 p;
  p.jaw = 0.5;
  for (int k = 0; k <= 400; ++k) {
    p.insertion = 0.15 + std::min(0.03, 1e-4 * k);  // to about 2 cm below the top, then hold
    const ToolGeometry g = tool_geometry(scene_->tools[0], p);
    organ.step(&g, p.jaw, 1e-3, t);
  }
  const double before = t.device_force.norm();
  ASSERT_GT(before, 0.5);
  ContactTick lost;
  organ.step(nullptr, p.jaw, 1e-3, lost);
  EXPECT_EQ(lost.device_force.norm(), 0.0);
  const ToolGeometry g = tool_geometry(scene_->tools[0], p);
  organ.step(&g, p.jaw, 1e-3, t);
  std::cout << "[resume] shipped liver: " << t.device_force.norm() << " N in the first tick back (before the loss "
            << before << " N)\n";
  EXPECT_NEAR(t.device_force.norm(), before, 1e-6 * before);
  EXPECT_GT(organ.contact_entries(), 3);
}

// A model swapped in between two ticks (as a cut will: a new model, the next topology generation). The tick that
// takes it allocates nothing and frees nothing (the replaced instance is still there for collect_retired() to free
// off the loop); from that tick the organ is the new model: its force is, bit for bit, the force of an instance built
// on that model alone for the same input.
TEST_F(LiverOrganTest, ModelSwappedBetweenTwoTicksAllocatesNothingAndActsAsTheNewModel) {
  LiverOrgan organ(*scene_, SURGSIM_TEST_CACHE_DIR, nullptr);  // its own (the fixture's is shared)
  ASSERT_EQ(organ.model().generation, 0u);
  // The next model: the same mesh, twice as stiff (its own tensors) and linear (the shipped curves are measured for
  // the shipped material), generation 1.
  liver::LiverModelSource stiffer{scene_->material, scene_->fixed, nonlinear::NonlinearSpec{}, false, scene_->file};
  stiffer.material.young_modulus *= 2;
  const std::shared_ptr<const liver::LiverModel> next =
      liver::build_liver_model(mesher::load_scene_mesh(*scene_, SURGSIM_TEST_CACHE_DIR), stiffer,
                               SURGSIM_TEST_CACHE_DIR, nullptr, 1);
  liver::LiverInstance alone(next, scene_->tools, scene_->liver.deformation);

  ContactTick t;
  organ.step(nullptr, 0.5, 1e-3, t);
  Pose5 p;
  p.jaw = 0.5;
  for (int k = 0; k <= 300; ++k) {  // to about 1 cm below the top, then hold
    p.insertion = 0.15 + std::min(0.02, 1e-4 * k);
    const ToolGeometry g = tool_geometry(scene_->tools[0], p);
    organ.step(&g, p.jaw, 1e-3, t);
  }
  const double before = t.device_force.norm();
  ASSERT_GT(before, 0.1);
  organ.post_model(next);  // off the loop: builds the new instance
  EXPECT_TRUE(organ.model_pending());
  EXPECT_EQ(organ.model().generation, 0u);  // not before the loop's next step

  const ToolGeometry g = tool_geometry(scene_->tools[0], p);
  ContactTick swapped;
  long allocations = 0;
  {
    test::AllocationCounter counter;
    organ.step(&g, p.jaw, 1e-3, swapped);
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0) << "the swap tick allocated";
  EXPECT_FALSE(organ.model_pending());
  EXPECT_EQ(organ.model().generation, 1u);
  EXPECT_EQ(&organ.model(), next.get());  // shared, not copied

  ContactTick reference;
  alone.contacts().step(g, p.jaw, reference, 1e-3);
  for (int c = 0; c < 3; ++c) EXPECT_EQ(swapped.device_force[c], reference.device_force[c]) << "component " << c;
  std::cout << "[swap] shipped liver held 1 cm deep: " << before << " N before, " << swapped.device_force.norm()
            << " N in the first tick on the twice-as-stiff model\n";
  EXPECT_GT(swapped.device_force.norm(), 1.2 * before);  // a stiffer liver pushes back harder at the same depth

  EXPECT_TRUE(organ.collect_retired());  // the generation-0 instance, freed here
  EXPECT_FALSE(organ.collect_retired());
  // A second swap (back to a model of generation 0's material) is taken the same way.
  organ.post_model(next);
  organ.step(&g, p.jaw, 1e-3, swapped);
  EXPECT_FALSE(organ.model_pending());
  EXPECT_EQ(swapped.device_force, reference.device_force);
}

// A liver whose rotation or tracker thread is bound to its instance refuses a model swap and says why.
TEST_F(LiverOrganTest, CorotationalLiverRefusesAModelSwap) {
  Scene corotational = *scene_;
  corotational.liver.deformation = compliance::LiverDeformation::kCorotational;
  LiverOrgan organ(corotational, SURGSIM_TEST_CACHE_DIR, nullptr);
  try {
    organ.post_model(nullptr);
    FAIL() << "a corotational liver took a model swap";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("needs liver.deformation linear (this liver is corotational"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace surgsim
