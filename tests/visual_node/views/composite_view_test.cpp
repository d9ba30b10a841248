// The picture of the operating field (config/abdomen.yaml, views/composite_view.h) through the real OSMesa renderer:
// an object-id picture of the shipped frame (each organ flat in its own colour: Renderer::set_id_colour) in which every
// organ covers at least 3 % of the picture, and the shipped trajectories' instruments in view all along.
#include "views/composite_view.h"

#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "intestine/intestine_model.h"
#include "render/renderer.h"
#include "tool/trajectory.h"
#include "views/intestine_view.h"

using namespace surgsim::scene;
using namespace surgsim::tool;

namespace surgsim {
namespace {

Scene shipped_field() { return load_scene(std::string(SURGSIM_TEST_CONFIG_DIR) + "/abdomen.yaml"); }

// The field's views as the visual node builds them (mesh and tensors from the test cache), the bowel in its rest shape
// (as the haptic node publishes it before its first step).
std::unique_ptr<OrganView> field_view(const Scene& scene) {
  OrganViewOptions options;
  options.cache_dir = SURGSIM_TEST_CACHE_DIR;
  std::unique_ptr<OrganView> view = make_organ_view(scene, options);
  auto& field = dynamic_cast<CompositeView&>(*view);
  for (int k = 0; k < field.organ_count(); ++k) {
    if (scene.organs[static_cast<std::size_t>(k)].model != "intestine") continue;
    const intestine::IntestineModel model(scene.organ_scene(static_cast<std::size_t>(k)).intestine.params);
    const std::vector<double> x(model.rest().data(), model.rest().data() + model.rest().size());
    auto& bowel = dynamic_cast<IntestineOrganView&>(field.organ(k));
    EXPECT_TRUE(bowel.view().set_positions(x.data(), static_cast<int>(x.size() / 3)));
  }
  return view;
}

// Id colours, exact in 8 bits and far from the background (kBackgroundRgb) and from each other.
constexpr std::array<std::array<std::uint8_t, 3>, kMaxOrgans> kIds = {{{230, 25, 75},
                                                                       {60, 180, 75},
                                                                       {255, 225, 25},
                                                                       {0, 130, 200},
                                                                       {245, 130, 48},
                                                                       {145, 30, 180},
                                                                       {70, 240, 240},
                                                                       {240, 50, 230}}};

// Every organ the field holds is meant to be in view (the liver, the bowel and its mesentery, the wall, the floor and
// the ribs; the field has no organ behind the camera or outside the cavity, such as a spine, that would be exempt).
TEST(FieldPicture, EveryOrganCoversAtLeastThreePercentOfTheShippedFrame) {
  const Scene scene = shipped_field();
  std::unique_ptr<OrganView> view = field_view(scene);
  auto& field = dynamic_cast<CompositeView&>(*view);
  ASSERT_EQ(field.organ_count(), static_cast<int>(scene.organs.size()));
  auto renderer = make_renderer("osmesa", scene.visual.width, scene.visual.height);
  renderer->begin_frame(scene.visual.camera);
  for (const int k : field.draw_order()) {
    const auto& id = kIds[static_cast<std::size_t>(k)];
    renderer->set_id_colour(Eigen::Vector3f(id[0], id[1], id[2]) / 255.0f);
    field.organ(k).draw(*renderer);
  }
  renderer->clear_id_colour();
  renderer->end_frame();
  Image image;
  ASSERT_TRUE(renderer->read_image(image));
  EXPECT_EQ(renderer->counts().gl_errors, 0u);
  EXPECT_EQ(renderer->counts().rejected, 0u);

  // Pixels per organ.
  std::vector<long> pixels(scene.organs.size(), 0);
  long other = 0;
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      const std::uint8_t* p = image.at(x, y);
      bool found = false;
      for (std::size_t k = 0; k < scene.organs.size() && !found; ++k) {
        found = p[0] == kIds[k][0] && p[1] == kIds[k][1] && p[2] == kIds[k][2];
        if (found) ++pixels[k];
      }
      if (!found) ++other;
    }
  }
  const double total = static_cast<double>(image.width) * image.height;
  for (std::size_t k = 0; k < scene.organs.size(); ++k) {
    std::printf("organ '%s' (%s): %.1f %% of the picture\n", scene.organs[k].name.c_str(),
                scene.organs[k].model.c_str(), 100.0 * static_cast<double>(pixels[k]) / total);
    EXPECT_GE(static_cast<double>(pixels[k]) / total, 0.03) << "organ '" << scene.organs[k].name << "'";
  }
  std::printf("no organ: %.1f %%\n", 100.0 * static_cast<double>(other) / total);
}

// No sample of `trajectory_file` at which an instrument's tip is behind the camera or outside the picture, for any
// instrument of the scene.
void expect_instruments_in_view(const Scene& scene, const std::string& trajectory_file) {
  const MultiTrajectory trajectory = MultiTrajectory::load(trajectory_file);
  const Eigen::Matrix4f view = view_matrix(scene.visual.camera);
  const int w = scene.visual.width, h = scene.visual.height;
  for (std::size_t i = 0; i < scene.tools.size(); ++i) {
    int column = trajectory.find(scene.tools[i].name);
    if (column < 0) column = static_cast<int>(i);
    ASSERT_LT(column, trajectory.instruments());
    int outside = 0;
    for (std::size_t k = 0; k < trajectory.size(); ++k) {
      if (!trajectory.valid(k, column)) continue;
      const Eigen::Vector3f tip = tool_geometry(scene.tools[i], trajectory.pose(k, column)).tip.cast<float>();
      const Eigen::Vector2f px = project_to_pixel(scene.visual.camera, w, h, tip);
      const bool in_front = (view * tip.homogeneous()).z() < 0.0f;
      if (!(in_front && px.x() >= 0 && px.x() < w && px.y() >= 0 && px.y() < h)) ++outside;
    }
    EXPECT_EQ(outside, 0) << trajectory_file << ": instrument '" << scene.tools[i].name
                          << "': samples with its tip out of the picture";
  }
}

// The instruments of the scene's trajectory: each tip in front of the camera and inside the picture at every sample.
TEST(FieldPicture, TheShippedTrajectorysInstrumentsStayInView) {
  const Scene scene = shipped_field();
  ASSERT_FALSE(scene.trajectory.empty());
  expect_instruments_in_view(scene, scene.trajectory);
}

// The same for the field's second trajectory (the probe lifting the liver's edge into the ribs).
TEST(FieldPicture, TheLiftTrajectorysInstrumentsStayInView) {
  expect_instruments_in_view(shipped_field(), std::string(SURGSIM_TEST_CONFIG_DIR) + "/trajectories/abdomen_lift.csv");
}

}  // namespace
}  // namespace surgsim
