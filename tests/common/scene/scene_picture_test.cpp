// The picture's keys of a scene (scene/scene.h): the scope camera (a laparoscope through a port, optionally oblique),
// visual.render (markers, the scope light and its falloff, wet speculars) and each organ's colour; none of them enters
// the scene hash. Their errors, which name the file, the line and the key, are SceneError's cases (scene_test.cpp).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <string>

#include "scene/scene.h"
#include "support/test_files.h"

using namespace surgsim::scene;

namespace surgsim {
namespace {

namespace fs = std::filesystem;

const std::string kHead = "name: t\nmesh: {generate: liver}\n";  // 2 lines
constexpr double kDeg = 3.14159265358979323846 / 180.0;

Scene load_text(const std::string& file, const std::string& yaml) {
  const fs::path dir = test::fresh_test_dir("scene_picture_test_");
  return load_scene(test::write_file(dir / file, yaml));
}

TEST(ScenePicture, ScopeCameraPutsTheEyeAtTheTipAndLooksAlongTheShaft) {
  const Scene s = load_text("s.yaml", kHead +
                                          "visual:\n"
                                          "  camera: {port: [0.1, 0, 0.1], target: [0, 0, 0], insertion: 0.05, "
                                          "fov_deg: 70}\n");
  const Camera& c = s.visual.camera;
  EXPECT_TRUE(c.scope);
  const Eigen::Vector3d shaft = Eigen::Vector3d(-1, 0, -1).normalized();
  EXPECT_NEAR((c.eye - (Eigen::Vector3d(0.1, 0, 0.1) + 0.05 * shaft)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((c.target - Eigen::Vector3d::Zero()).norm(), 0.0, 1e-12) << "a 0 degree scope looks at its target";
  EXPECT_DOUBLE_EQ(c.fov_deg, 70.0);
  // The scope's light and no markers unless asked.
  EXPECT_EQ(s.visual.render.light, RenderSpec::Light::kScope);
  EXPECT_FALSE(s.visual.render.markers);
  // The eye/target form is read as before, with the studio lights.
  const Scene e = load_text("e.yaml", kHead + "visual:\n  camera: {eye: [1, 0, 0], target: [0, 0, 0]}\n");
  EXPECT_FALSE(e.visual.camera.scope);
  EXPECT_EQ(e.visual.camera.eye, Eigen::Vector3d(1, 0, 0));
  EXPECT_EQ(e.visual.render.light, RenderSpec::Light::kStudio);
  EXPECT_FALSE(e.visual.render.markers);
}

TEST(ScenePicture, ObliqueScopeTurnsTheViewTowardsUpAndRollsAboutTheShaft) {
  // Shaft straight down (-z) from the port, up +y: a 30 degree scope looks 30 degrees towards +y.
  const std::string head =
      kHead + "visual:\n  camera: {port: [0, 0, 0.2], target: [0, 0, 0], up: [0, 1, 0], insertion: 0.1, angle_deg: 30";
  const Scene s = load_text("s.yaml", head + "}\n");
  const Camera& c = s.visual.camera;
  const Eigen::Vector3d view = (c.target - c.eye).normalized();
  EXPECT_NEAR((c.eye - Eigen::Vector3d(0, 0, 0.1)).norm(), 0.0, 1e-12);
  EXPECT_NEAR(std::acos(view.dot(-Eigen::Vector3d::UnitZ())), 30 * kDeg, 1e-9);
  EXPECT_NEAR(view.x(), 0.0, 1e-12);
  EXPECT_GT(view.y(), 0.0);
  EXPECT_NEAR((c.target - c.eye).norm(), 0.1, 1e-12) << "the target as far from the eye as the aimed point";
  // Rolled 90 degrees about the shaft (right-handed about -z): towards +x.
  const Scene r = load_text("r.yaml", head + ", roll_deg: 90}\n");
  const Eigen::Vector3d rolled = (r.visual.camera.target - r.visual.camera.eye).normalized();
  EXPECT_NEAR(std::acos(rolled.dot(-Eigen::Vector3d::UnitZ())), 30 * kDeg, 1e-9);
  EXPECT_NEAR(rolled.y(), 0.0, 1e-12);
  EXPECT_NEAR(std::abs(rolled.x()), std::sin(30 * kDeg), 1e-9);
}

TEST(ScenePicture, RenderKeysAndOrganColoursAreReadAndNotHashed) {
  const std::string organs =
      "name: f\n"
      "organs:\n"
      "  - {name: wall, model: rigid, rigid: {generate: plane, size: [0.2, 0.2, 0]}, colour: [0.7, 0.3, 0.3]}\n"
      "  - {name: ribs, model: rigid, rigid: {generate: box, size: [0.02, 0.02, 0.02]}, "
      "placement: {translation: [0, 0, 0.1]}, color: [0.9, 0.9, 0.8]}\n"
      "  - {name: floor, model: rigid, rigid: {generate: plane, size: [0.3, 0.3, 0]}, placement: {translation: [0, 0, "
      "-0.1]}}\n";
  const Scene s = load_text("f.yaml", organs +
                                          "visual:\n"
                                          "  camera: {port: [0, -0.1, 0.1], target: [0, 0, 0]}\n"
                                          "  render: {markers: true, falloff: [0.5, 1, 40], wet: 0.5}\n");
  EXPECT_TRUE(s.visual.render.markers);
  EXPECT_EQ(s.visual.render.falloff, Eigen::Vector3d(0.5, 1, 40));
  EXPECT_DOUBLE_EQ(s.visual.render.wet, 0.5);
  ASSERT_EQ(s.organs.size(), 3u);
  EXPECT_TRUE(s.organs[0].has_colour);
  EXPECT_EQ(s.organs[0].colour, Eigen::Vector3d(0.7, 0.3, 0.3));
  EXPECT_TRUE(s.organs[1].has_colour) << "either spelling";
  EXPECT_EQ(s.organs[1].colour, Eigen::Vector3d(0.9, 0.9, 0.8));
  EXPECT_FALSE(s.organs[2].has_colour);
  EXPECT_TRUE(s.organ_scene(1).organs[0].has_colour) << "an organ's one-organ scene keeps its colour";
  // The same field without any of the picture's keys has the same hash.
  const Scene plain = load_text("p.yaml",
                                "name: f\n"
                                "organs:\n"
                                "  - {name: wall, model: rigid, rigid: {generate: plane, size: [0.2, 0.2, 0]}}\n"
                                "  - {name: ribs, model: rigid, rigid: {generate: box, size: [0.02, 0.02, 0.02]}, "
                                "placement: {translation: [0, 0, 0.1]}}\n"
                                "  - {name: floor, model: rigid, rigid: {generate: plane, size: [0.3, 0.3, 0]}, "
                                "placement: {translation: [0, 0, -0.1]}}\n");
  EXPECT_EQ(s.hash(), plain.hash());
  // light: studio with an eye/target camera by default; asked for explicitly with either camera.
  const Scene studio =
      load_text("st.yaml",
                kHead + "visual:\n  camera: {port: [0, -0.1, 0.1], target: [0, 0, 0]}\n  render: {light: studio}\n");
  EXPECT_EQ(studio.visual.render.light, RenderSpec::Light::kStudio);
  // The single-organ form takes a colour at the top level.
  const Scene one = load_text("o.yaml", kHead + "colour: [0.5, 0.2, 0.1]\n");
  EXPECT_TRUE(one.organs[0].has_colour);
}

}  // namespace
}  // namespace surgsim
