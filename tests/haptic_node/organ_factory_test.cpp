// The factory is the only place that looks at the scene's model: each shipped model gets its own implementation, a
// model the node does not build is an error naming the scene file and the key.
#include <gtest/gtest.h>

#include <string>

#include "core/error.h"
#include "organ.h"
#include "support/error_test_util.h"

using namespace surgsim::contact;
using namespace surgsim::scene;

namespace surgsim {
namespace {

TEST(OrganFactory, UnknownModelNamesTheFileAndKey) {
  Scene s;
  s.file = "/scenes/kidney.yaml";
  s.model = "kidney";
  const std::string e = test::error_of([&] { make_haptic_organ(s, SURGSIM_TEST_CACHE_DIR, 10, nullptr); });
  EXPECT_NE(e.find("/scenes/kidney.yaml: key 'model': 'kidney'"), std::string::npos) << e;
}

TEST(OrganFactory, IntestineBuildsTheBodyAndNoLiver) {
  const Scene s = load_scene(resolve_scene_path("intestine"));
  const auto organ = make_haptic_organ(s, SURGSIM_TEST_CACHE_DIR, 10, nullptr);
  EXPECT_STREQ(organ->model_name(), "intestine");
  EXPECT_EQ(organ->mesh_hash(), 0u);    // no tetrahedral mesh
  EXPECT_EQ(organ->tensor_hash(), 0u);  // no tensors
  EXPECT_EQ(organ->contact_entries(), 0);
  EXPECT_EQ(organ->node_count(), static_cast<std::uint32_t>(s.intestine.params.rows * s.intestine.params.columns));
}

TEST(OrganFactory, LiverBuildsTensorsAndContactsWithoutTheTool) {
  const Scene s = load_scene(resolve_scene_path("liver"));
  const auto organ = make_haptic_organ(s, SURGSIM_TEST_CACHE_DIR, 10, nullptr);
  EXPECT_STREQ(organ->model_name(), "liver");
  EXPECT_NE(organ->mesh_hash(), 0u);
  EXPECT_NE(organ->tensor_hash(), 0u);
  // Input lost (no tool): contacts dropped, zero force.
  ContactTick out;
  organ->step(nullptr, 0.0, 1e-3, out);
  EXPECT_EQ(organ->contacts(), 0);
  EXPECT_TRUE(out.device_force.isZero(0));
}

}  // namespace
}  // namespace surgsim
