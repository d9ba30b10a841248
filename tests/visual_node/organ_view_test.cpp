// The organ views behind the visual node's app: the factory picks the scene's organ, and each view answers the
// app's questions (hashes, deformation, markers, VTK, stats) without DDS or GL (null renderer).
#include "organ_view.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>

#include "surgsim_types.h"
#include "views/intestine_view.h"
#include "views/liver_view.h"
#include "render/renderer.h"

namespace surgsim {
namespace {

Scene shipped(const std::string& name) { return load_scene(std::string(SURGSIM_TEST_CONFIG_DIR) + "/" + name); }

OrganViewOptions test_options() {
  OrganViewOptions o;
  o.cache_dir = SURGSIM_TEST_CACHE_DIR;
  return o;
}

TEST(OrganView, SceneHashMixesTheMeshHash) {
  const Scene scene = shipped("intestine.yaml");
  EXPECT_EQ(visual_scene_hash(scene, 0), scene.hash());  // no tetrahedral mesh: the scene's own hash
  EXPECT_NE(visual_scene_hash(scene, 1), scene.hash());
  EXPECT_NE(visual_scene_hash(scene, 1), visual_scene_hash(scene, 2));
}

TEST(OrganView, IntestineSceneGetsTheIntestineView) {
  const Scene scene = shipped("intestine.yaml");
  std::unique_ptr<OrganView> organ = make_organ_view(scene, test_options());
  auto* intestine = dynamic_cast<IntestineOrganView*>(organ.get());
  ASSERT_NE(intestine, nullptr);
  EXPECT_EQ(organ->mesh_hash(), 0u);
  EXPECT_EQ(organ->tensor_hash(), 0u);
  EXPECT_EQ(organ->surface_triangles(), 0);
  EXPECT_EQ(organ->lod(), static_cast<std::uint32_t>(intestine::kTubeMaxLod));
  EXPECT_EQ(intestine->view().skinning(), intestine::TubeSkinning::kGpu);

  // Contact frames do not deform it; without DDS there is no body state to take.
  msg::ContactFrame frame;
  EXPECT_LT(organ->update(&frame, true), 0.0);
  EXPECT_EQ(organ->contacts_shown(), 0);
  EXPECT_EQ(organ->max_displacement(), 0.0);
  EXPECT_FALSE(organ->write_vtk("/nonexistent/never.vtk"));
  EXPECT_EQ(organ->deform_errors(), 0u);

  auto renderer = make_renderer("null", 64, 48);
  organ->attach(*renderer);  // the null backend counts skinned tubes: GPU skinning kept
  EXPECT_EQ(intestine->view().skinning(), intestine::TubeSkinning::kGpu);
  renderer->begin_frame(scene.visual.camera);
  organ->draw(*renderer);
  organ->draw_markers(*renderer);
  renderer->end_frame();
  organ->frame_done(0.001);
  EXPECT_EQ(renderer->counts().surfaces, 0u);  // nothing before the first body state

  nlohmann::json j;
  organ->add_stats(j);
  EXPECT_EQ(j["model_built"], "intestine");
  ASSERT_TRUE(j.contains("intestine"));
  EXPECT_EQ(j["lod_mean"], j["intestine"]["lod_mean"]);
  EXPECT_EQ(j["lod_target_fps"], j["intestine"]["target_fps"]);
  EXPECT_FALSE(j.contains("visible_nodes"));  // the app's default (0) stands

  std::ostringstream init, summary;
  organ->print_init(init);
  EXPECT_NE(init.str().find("visual_node: intestine: tube skinned on the GPU"), std::string::npos) << init.str();
  organ->print_summary(summary, j);
  EXPECT_NE(summary.str().find("0 body states received"), std::string::npos) << summary.str();
}

TEST(OrganView, CpuSkinningIsPassedThrough) {
  OrganViewOptions o = test_options();
  o.tube_skinning = intestine::TubeSkinning::kCpu;
  std::unique_ptr<OrganView> organ = make_organ_view(shipped("intestine.yaml"), o);
  EXPECT_EQ(dynamic_cast<IntestineOrganView&>(*organ).view().skinning(), intestine::TubeSkinning::kCpu);
}

// The liver view on the shipped plate (a small liver-model scene; mesh and tensors from the test cache).
TEST(OrganView, LiverSceneGetsTheLiverViewThatDeformsAndMarksContacts) {
  const Scene scene = shipped("plate.yaml");
  std::unique_ptr<OrganView> organ = make_organ_view(scene, test_options());
  auto* liver = dynamic_cast<LiverView*>(organ.get());
  ASSERT_NE(liver, nullptr);
  EXPECT_NE(organ->mesh_hash(), 0u);
  EXPECT_NE(organ->tensor_hash(), 0u);
  EXPECT_GT(organ->surface_triangles(), 0);
  EXPECT_EQ(organ->lod(), 0u);

  // Before any frame: the rest shape, no contacts.
  EXPECT_LT(organ->update(nullptr, false), 0.0);
  EXPECT_EQ(organ->contacts_shown(), 0);
  EXPECT_EQ(organ->max_displacement(), 0.0);

  // One contact on a visible node, pressing down.
  const int node = liver->deformer().visible_nodes()[liver->deformer().visible_nodes().size() / 2];
  msg::ContactFrame frame;
  msg::ContactEntry e;
  e.node(static_cast<std::uint32_t>(node));
  e.lambda().z(-0.2);
  frame.contacts().push_back(e);
  frame.direction().z(-1.0);
  EXPECT_GE(organ->update(&frame, true), 0.0);
  EXPECT_EQ(organ->contacts_shown(), 1);
  EXPECT_GT(organ->max_displacement(), 0.0);
  EXPECT_EQ(organ->deform_errors(), 0u);
  const double shown = organ->max_displacement();
  // Not fresh: the same shape is kept (no deformation work), the contact still shown.
  EXPECT_LT(organ->update(&frame, false), 0.0);
  EXPECT_EQ(organ->max_displacement(), shown);
  EXPECT_EQ(organ->contacts_shown(), 1);

  auto renderer = make_renderer("null", 64, 48);
  renderer->begin_frame(scene.visual.camera);
  organ->draw(*renderer);
  organ->draw_markers(*renderer);
  renderer->end_frame();
  EXPECT_EQ(renderer->counts().surfaces, 1u);
  EXPECT_EQ(renderer->counts().points, 1u);

  const std::string vtk =
      (std::filesystem::temp_directory_path() / ("surgsim_liver_view_" + std::to_string(::getpid()) + ".vtk")).string();
  EXPECT_TRUE(organ->write_vtk(vtk));
  EXPECT_GT(std::filesystem::file_size(vtk), 0u);
  std::filesystem::remove(vtk);

  nlohmann::json j;
  organ->add_stats(j);
  EXPECT_EQ(j["model_built"], "liver");
  EXPECT_EQ(j["visible_nodes"].get<std::size_t>(), liver->deformer().visible_nodes().size());
  EXPECT_GT(j["tensor_rows"].get<int>(), 0);
  EXPECT_FALSE(j.contains("intestine"));
}

}  // namespace
}  // namespace surgsim
