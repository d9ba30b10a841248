// The organ views behind the visual node's app: the factory picks the scene's organ, and each view answers the
// app's questions (hashes, deformation, markers, VTK, stats) without DDS or GL (null renderer).
#include "organ_view.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>

#include "instruments.h"
#include "render/renderer.h"
#include "support/contact_frame_util.h"
#include "surgsim_types.h"
#include "views/intestine_view.h"
#include "views/liver_view.h"

using namespace surgsim::tool;
using namespace surgsim::scene;

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

  // Contact frames do not deform it; without DDS there is no body state to take (nor its instruments: the app draws
  // those of the contact frame).
  msg::ContactFrame frame;
  EXPECT_LT(organ->update(&frame, true), 0.0);
  EXPECT_EQ(organ->instruments(), nullptr);
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

// An organ the visual node cannot draw is refused with the file and the key, as the haptic node's factory refuses one
// it cannot simulate (it used to be drawn as a liver).
TEST(OrganView, UnknownModelIsRefusedWithTheFileAndKey) {
  Scene scene = shipped("plate.yaml");
  scene.model = "spleen";
  try {
    make_organ_view(scene, test_options());
    FAIL() << "model 'spleen' was given a view";
  } catch (const std::exception& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("plate.yaml: key 'model': 'spleen' is not built into this visual node"), std::string::npos)
        << what;
  }
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

  // One contact on a visible node, pressing down, of the scene's one instrument.
  const int node = liver->deformer().visible_nodes()[liver->deformer().visible_nodes().size() / 2];
  const msg::ContactFrame frame = testing::press_frame(node, -0.2);
  EXPECT_GE(organ->update(&frame, true), 0.0);
  EXPECT_EQ(organ->instruments(), nullptr);  // the app draws the contact frame's instruments
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

// Two instruments on the plate: the contacts of both deform it together, both are marked.
TEST(OrganView, LiverViewTakesTheContactsOfEveryInstrument) {
  Scene scene = shipped("plate.yaml");
  scene.tools.push_back(scene.tools[0]);
  scene.tools[1].name = "probe";
  std::unique_ptr<OrganView> organ = make_organ_view(scene, test_options());
  const auto& visible = dynamic_cast<LiverView&>(*organ).deformer().visible_nodes();
  msg::ContactFrame frame;
  for (std::uint32_t i = 0; i < 2; ++i) {
    msg::ContactEntry e;
    e.node(static_cast<std::uint32_t>(visible[visible.size() / 3 + i * visible.size() / 3]));
    e.instrument(i);
    e.lambda().z(-0.2);
    frame.contacts().push_back(e);
    msg::InstrumentState tool;
    tool.instrument(i);
    tool.direction().z(-1.0);
    frame.instruments().push_back(tool);
  }
  EXPECT_GE(organ->update(&frame, true), 0.0);
  EXPECT_EQ(organ->contacts_shown(), 2);
  EXPECT_EQ(organ->deform_errors(), 0u);
  const double both = organ->max_displacement();
  EXPECT_GT(both, 0.0);
  auto renderer = make_renderer("null", 64, 48);
  organ->draw_markers(*renderer);
  EXPECT_EQ(renderer->counts().points, 2u);

  // Instrument 1 alone dents the plate less than both together (the plate has no non-linear law: a linear sum).
  frame.contacts().erase(frame.contacts().begin());
  EXPECT_GE(organ->update(&frame, true), 0.0);
  EXPECT_EQ(organ->contacts_shown(), 1);
  EXPECT_GT(organ->max_displacement(), 0.0);
  EXPECT_LT(organ->max_displacement(), both);
}

// Wire v3: a frame carries every organ's contact entries; a liver view draws only those of its organ (its index in the
// scene's organs list, OrganViewOptions::organ_index) and skips the others, whose nodes are another mesh's.
TEST(OrganView, LiverViewSkipsTheContactsOfOtherOrgans) {
  const Scene scene = shipped("plate.yaml");
  const auto entry = [](std::uint32_t node, std::uint32_t organ) {
    msg::ContactEntry e;
    e.node(node);
    e.instrument(0);
    e.organ(organ);
    e.lambda().z(-0.2);
    return e;
  };
  msg::InstrumentState tool;
  tool.instrument(0);
  tool.direction().z(-1.0);
  for (const int index : {0, 1}) {
    OrganViewOptions options = test_options();
    options.organ_index = index;
    std::unique_ptr<OrganView> organ = make_organ_view(scene, options);
    const auto& liver = dynamic_cast<LiverView&>(*organ);
    const auto& visible = liver.deformer().visible_nodes();
    const auto node = [&](std::size_t k) { return static_cast<std::uint32_t>(visible[k * visible.size() / 4]); };
    // This organ's contact alone.
    msg::ContactFrame own;
    own.instruments().push_back(tool);
    own.contacts().push_back(entry(node(1), static_cast<std::uint32_t>(index)));
    EXPECT_GE(organ->update(&own, true), 0.0);
    ASSERT_EQ(organ->contacts_shown(), 1);
    const double alone = organ->max_displacement();
    EXPECT_GT(alone, 0.0);
    // The same contact among two of another organ (one of them on a node this mesh also has): the same shape.
    msg::ContactFrame mixed;
    mixed.instruments().push_back(tool);
    mixed.contacts().push_back(entry(node(2), static_cast<std::uint32_t>(1 - index)));
    mixed.contacts().push_back(entry(node(1), static_cast<std::uint32_t>(index)));
    mixed.contacts().push_back(entry(999999, 7));  // not even a node of this mesh
    EXPECT_GE(organ->update(&mixed, true), 0.0);
    EXPECT_EQ(organ->contacts_shown(), 1) << "organ " << index;
    EXPECT_EQ(organ->deform_errors(), 0u) << "another organ's node was applied to this mesh";
    EXPECT_DOUBLE_EQ(organ->max_displacement(), alone) << "organ " << index;
    EXPECT_EQ(liver.other_organ_contacts(), 2u);
    // A later frame (not fresh) still shows this organ's contact only.
    EXPECT_LT(organ->update(&mixed, false), 0.0);
    EXPECT_EQ(organ->contacts_shown(), 1);
    auto renderer = make_renderer("null", 64, 48);
    organ->draw_markers(*renderer);
    EXPECT_EQ(renderer->counts().points, 1u) << "one marker: this organ's contact";
  }
}

msg::InstrumentState instrument_state(std::uint32_t index, double insertion, double pitch = 0) {
  msg::InstrumentState s;
  s.instrument(index);
  s.pose().insertion(insertion);
  s.pose().pitch(pitch);
  s.pose().jaw(0.3);
  s.direction().z(-1.0);
  return s;
}

TEST(Instruments, TakesTheStatesOfTheScenesToolsAndCountsTheOthers) {
  msg::ContactFrame frame;
  frame.instruments().push_back(instrument_state(1, 0.12, 0.2));
  frame.instruments().push_back(instrument_state(0, 0.10));
  frame.instruments().push_back(instrument_state(2, 0.10));  // a third instrument: the scene has two
  frame.instruments().push_back(instrument_state(1, 0.05));  // instrument 1 again
  InstrumentPoses poses;
  take_instruments(frame.instruments(), 2, poses);
  EXPECT_TRUE(poses.present[0]);
  EXPECT_TRUE(poses.present[1]);
  EXPECT_FALSE(poses.present[2]);
  EXPECT_EQ(poses.count(), 2);
  EXPECT_EQ(poses.ignored, 2);
  EXPECT_EQ(poses.pose[0].insertion, 0.10);
  EXPECT_EQ(poses.pose[1].insertion, 0.12);  // the first state of instrument 1
  EXPECT_EQ(poses.pose[1].pitch, 0.2);
  EXPECT_EQ(poses.pose[1].jaw, 0.3);
  EXPECT_EQ(poses.direction[1], Eigen::Vector3d(0, 0, -1));

  // The next frame replaces them: an instrument it does not carry is absent, with no direction.
  frame.instruments().resize(1);
  take_instruments(frame.instruments(), 2, poses);
  EXPECT_FALSE(poses.present[0]);
  EXPECT_TRUE(poses.present[1]);
  EXPECT_EQ(poses.direction[0], Eigen::Vector3d::Zero());
  EXPECT_EQ(poses.ignored, 0);
  // An empty frame: nothing to draw.
  frame.instruments().clear();
  take_instruments(frame.instruments(), 2, poses);
  EXPECT_EQ(poses.count(), 0);
}

// A frame with two instruments draws both, each with its own tool spec (trocar, shaft radius) and colour, on the
// real OSMesa renderer; an instrument the frame does not carry is not drawn.
TEST(Instruments, EveryInstrumentOfAFrameIsDrawnInItsOwnColour) {
  std::vector<ToolSpec> tools(2);
  tools[0].name = "grasper";
  tools[0].trocar = {-0.06, 0.0, 0.20};
  tools[0].shaft_radius = 0.004;
  tools[1].name = "probe";
  tools[1].trocar = {0.06, 0.0, 0.20};
  tools[1].shaft_radius = 0.004;
  Camera camera;
  camera.eye = {0.0, -0.5, 0.12};
  camera.target = {0.0, 0.0, 0.12};
  camera.up = {0, 0, 1};
  camera.fov_deg = 35;
  constexpr int kW = 320, kH = 240;

  msg::ContactFrame frame;
  frame.instruments().push_back(instrument_state(0, 0.16));
  frame.instruments().push_back(instrument_state(1, 0.12, 0.25));  // tilted
  frame.instruments().push_back(instrument_state(3, 0.12));        // no such tool: ignored
  InstrumentPoses poses;
  take_instruments(frame.instruments(), static_cast<int>(tools.size()), poses);
  ASSERT_EQ(poses.ignored, 1);

  auto renderer = make_renderer("osmesa", kW, kH);
  const auto render = [&](Image& image) {
    renderer->begin_frame(camera);
    const int drawn = draw_instruments(*renderer, tools, poses);
    renderer->end_frame();
    EXPECT_TRUE(renderer->read_image(image));
    return drawn;
  };
  // Pixels across instrument i's shaft halfway from its trocar to its tip: drawn, grey, blue.
  struct Across {
    int drawn = 0, grey = 0, blue = 0;
  };
  const auto across = [&](const Image& image, int i) {
    const ToolGeometry g = tool_geometry(tools[static_cast<std::size_t>(i)], poses.pose[static_cast<std::size_t>(i)]);
    const Eigen::Vector2f c = project_to_pixel(camera, kW, kH, (0.5 * (g.trocar + g.tip)).cast<float>());
    Across a;
    for (int dx = -10; dx <= 10; ++dx) {
      const std::uint8_t* p = image.at(static_cast<int>(c.x()) + dx, static_cast<int>(c.y()));
      if (p[0] == kBackgroundRgb[0] && p[1] == kBackgroundRgb[1] && p[2] == kBackgroundRgb[2]) continue;
      ++a.drawn;
      a.grey += std::abs(p[0] - p[2]) < 40 ? 1 : 0;
      a.blue += p[2] > p[0] + 60 ? 1 : 0;
    }
    return a;
  };

  Image image;
  EXPECT_EQ(render(image), 2);
  EXPECT_EQ(renderer->counts().tools, 2u);
  EXPECT_EQ(renderer->counts().rejected, 0u);
  const Across first = across(image, 0), second = across(image, 1);
  EXPECT_GT(first.drawn, 3) << "instrument 0's shaft";
  EXPECT_EQ(first.grey, first.drawn) << "instrument 0 in grey";
  EXPECT_GT(second.drawn, 3) << "instrument 1's shaft";
  EXPECT_GE(second.blue, second.drawn - 1) << "instrument 1 in blue: " << second.blue << " of " << second.drawn;

  // Instrument 1 absent from the next frame: only instrument 0 is drawn.
  frame.instruments().erase(frame.instruments().begin() + 1);
  const Pose5 shown1 = poses.pose[1];
  take_instruments(frame.instruments(), static_cast<int>(tools.size()), poses);
  poses.pose[1] = shown1;  // where it was, to look there
  Image one;
  EXPECT_EQ(render(one), 1);
  EXPECT_EQ(across(one, 1).drawn, 0) << "an instrument the frame does not carry is not drawn";
  EXPECT_EQ(across(one, 0).drawn, first.drawn);
}

}  // namespace
}  // namespace surgsim
