// IntestineView without DDS or GL: body states in, tube and mesentery drawn on the null renderer, LOD control.
#include "views/intestine_view.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#include "intestine/intestine_model.h"
#include "render/renderer.h"

using namespace surgsim::scene;

namespace surgsim {
namespace {

Scene shipped_intestine() { return load_scene(std::string(SURGSIM_TEST_CONFIG_DIR) + "/intestine.yaml"); }

// The rest shape of the scene's model, as a BodyState carries it.
std::vector<double> rest_positions(const Scene& scene) {
  const intestine::IntestineModel model(scene.intestine.params);
  return std::vector<double>(model.rest().data(), model.rest().data() + model.rest().size());
}

TEST(IntestineView, DrawsTubeAndMesenteryOfABodyState) {
  const Scene scene = shipped_intestine();
  IntestineView view(scene, scene.hash(), intestine::TubeSkinning::kCpu);  // skinned vertices to check
  auto renderer = make_renderer("null", 64, 48);

  // Nothing to draw before the first body state.
  EXPECT_FALSE(view.has_body());
  renderer->begin_frame(scene.visual.camera);
  view.draw(*renderer);
  renderer->end_frame();
  EXPECT_EQ(renderer->counts().surfaces, 0u);

  const std::vector<double> x = rest_positions(scene);
  ASSERT_TRUE(view.set_positions(x.data(), static_cast<int>(x.size() / 3)));
  EXPECT_TRUE(view.has_body());
  EXPECT_EQ(view.lod(), intestine::kTubeMaxLod);  // starts at the finest level
  ASSERT_GT(view.tube_vertices(), 0);
  EXPECT_GT(view.tube_triangles(), 1000);
  // The tube surrounds the intestine's points: every vertex within about a radius of the axis' bounding box. The axis
  // is a spline through the points, which may bulge past their box by a small fraction of a segment where the curve
  // turns at the box's edge (0.9 mm, 2 % of a segment, in the shipped scene): 5 % of the mean segment is allowed.
  const Eigen::Map<const Eigen::Matrix3Xd> pts(x.data(), 3, scene.intestine.params.columns);
  const Eigen::Vector3f lo = pts.rowwise().minCoeff().cast<float>(), hi = pts.rowwise().maxCoeff().cast<float>();
  const double segment = scene.intestine.params.length / (scene.intestine.params.columns - 1);
  const float r = static_cast<float>(scene.intestine.params.intestine_radius * 1.01 + 0.05 * segment);
  for (int v = 0; v < view.tube_vertices(); ++v) {
    const Eigen::Vector3f p = view.tube_positions().row(v).transpose();
    ASSERT_TRUE(p.allFinite());
    ASSERT_TRUE(((p.array() >= lo.array() - r) && (p.array() <= hi.array() + r)).all())
        << v << " at " << p.transpose() << " box " << lo.transpose() << " .. " << hi.transpose() << " margin " << r;
  }
  renderer->begin_frame(scene.visual.camera);
  view.draw(*renderer);
  renderer->end_frame();
  EXPECT_EQ(renderer->counts().surfaces, 2u);  // mesentery and tube
  EXPECT_EQ(renderer->counts().rejected, 0u);
}

// The default path skins on the GPU: the view builds only the per-interval matrices (the CPU mesh's vertices are
// not written) and draws the tube with draw_skinned_tube; the same body gives the same matrices and counts as the
// CPU path, and set_skinning switches paths.
TEST(IntestineView, GpuSkinningIsTheDefaultAndSendsOnlyMatrices) {
  const Scene scene = shipped_intestine();
  IntestineView gpu(scene, scene.hash());
  IntestineView cpu(scene, scene.hash(), intestine::TubeSkinning::kCpu);
  EXPECT_EQ(gpu.skinning(), intestine::TubeSkinning::kGpu);
  const std::vector<double> x = rest_positions(scene);
  ASSERT_TRUE(gpu.set_positions(x.data(), static_cast<int>(x.size() / 3)));
  ASSERT_TRUE(cpu.set_positions(x.data(), static_cast<int>(x.size() / 3)));
  ASSERT_GT(gpu.tube().intervals, 0);
  EXPECT_EQ(gpu.tube().intervals, cpu.tube().intervals);
  EXPECT_EQ(gpu.tube_vertices(), cpu.tube_vertices());    // caps included
  EXPECT_EQ(gpu.tube_triangles(), cpu.tube_triangles());
  const auto n = static_cast<std::ptrdiff_t>(24 * gpu.tube().intervals);
  EXPECT_TRUE(std::equal(gpu.tube().skin.begin(), gpu.tube().skin.begin() + n, cpu.tube().skin.begin()));
  // The primitive drawn is the LOD's: its instance count times its body triangles is the tube's.
  const intestine::TubePrimitive& prim = gpu.tube_primitive();
  EXPECT_EQ(gpu.tube().intervals * prim.body_index_count + 2 * prim.cap_index_count, 3 * gpu.tube_triangles());
  EXPECT_EQ(gpu.stats()["tube_skinning"], "gpu");
  EXPECT_EQ(cpu.stats()["tube_skinning"], "cpu");

  auto renderer = make_renderer("null", 64, 48);
  renderer->begin_frame(scene.visual.camera);
  gpu.draw(*renderer);
  renderer->end_frame();
  EXPECT_EQ(renderer->counts().surfaces, 2u);  // mesentery and the skinned tube
  EXPECT_EQ(renderer->counts().rejected, 0u);

  // Switching to the CPU path rebuilds with vertices on the next update.
  gpu.set_skinning(intestine::TubeSkinning::kCpu);
  gpu.update();
  EXPECT_EQ(gpu.stats()["tube_skinning"], "cpu");
  for (int v = 0; v < gpu.tube_vertices(); ++v) {
    ASSERT_EQ(gpu.tube_positions().row(v), cpu.tube_positions().row(v)) << v;
  }
}

TEST(IntestineView, RefusesWrongCountsAndNonFiniteValues) {
  const Scene scene = shipped_intestine();
  IntestineView view(scene, scene.hash());
  std::vector<double> x = rest_positions(scene);
  EXPECT_FALSE(view.set_positions(x.data(), static_cast<int>(x.size() / 3) - 1));
  x[7] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(view.set_positions(x.data(), static_cast<int>(x.size() / 3)));
  EXPECT_FALSE(view.has_body());
  EXPECT_EQ(view.stats()["body_states_rejected"].get<int>(), 2);
}

// The probes drawn with the intestine are those of the body state shown (one probe per instrument, in step
// with the body); a refused state keeps the previous ones.
TEST(IntestineView, KeepsTheInstrumentsOfTheBodyStateShown) {
  const Scene scene = shipped_intestine();
  IntestineView view(scene, scene.hash());
  EXPECT_EQ(view.instruments().count(), 0);
  std::vector<double> x = rest_positions(scene);
  InstrumentPoses probes;
  probes.present[0] = true;
  probes.pose[0].insertion = 0.07;
  probes.ignored = 1;  // the state carried one instrument the scene does not have
  ASSERT_TRUE(view.set_positions(x.data(), static_cast<int>(x.size() / 3), &probes));
  EXPECT_TRUE(view.instruments().present[0]);
  EXPECT_EQ(view.instruments().pose[0].insertion, 0.07);
  EXPECT_EQ(view.stats()["instrument_states_ignored"].get<int>(), 1);

  InstrumentPoses moved = probes;
  moved.pose[0].insertion = 0.09;
  x[4] = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(view.set_positions(x.data(), static_cast<int>(x.size() / 3), &moved));
  EXPECT_EQ(view.instruments().pose[0].insertion, 0.07) << "a refused state changes nothing";
  // Positions alone (no instruments, e.g. a benchmark): the probes shown stay.
  x[4] = rest_positions(scene)[4];
  ASSERT_TRUE(view.set_positions(x.data(), static_cast<int>(x.size() / 3)));
  EXPECT_TRUE(view.instruments().present[0]);
}

// Frames whose work allows only half the target rate: the controller removes levels of detail (paper eq. 15), and
// frames that leave room bring them back.
TEST(IntestineView, FrameRateControllerLowersAndRaisesTheLod) {
  const Scene scene = shipped_intestine();
  IntestineView view(scene, scene.hash());
  const std::vector<double> x = rest_positions(scene);
  ASSERT_TRUE(view.set_positions(x.data(), static_cast<int>(x.size() / 3)));
  const double target = view.controller().params().target_hz;
  const int full = view.tube_triangles();
  for (int k = 0; k < 2000; ++k) {
    view.frame_done(2.0 / target);
    view.update();
  }
  EXPECT_LT(view.lod(), intestine::kTubeMaxLod);
  EXPECT_LT(view.tube_triangles(), full) << "the rebuilt tube follows the controller's LOD";
  const int low = view.lod();
  for (int k = 0; k < 4000; ++k) {
    view.frame_done(0.25 / target);
    view.update();
  }
  EXPECT_GT(view.lod(), low);
  const auto s = view.stats();
  EXPECT_EQ(s["target_fps"].get<double>(), target);
  EXPECT_EQ(s["lod_histogram"].size(), static_cast<std::size_t>(intestine::kTubeMaxLod + 1));
  EXPECT_GE(s["lod_mean"].get<double>(), 0.0);
}

// The shipped scene's rest shape drawn with OSMesa at the scene's camera, as the visual node draws it: pink-red tube
// pixels, many pinkish-yellow mesentery pixels whose intensity spans a wide range in many levels (lit, smooth: not
// one flat tan), and the abdominal backdrop around them (dark, not the flat clear colour, darker in the corners).
TEST(IntestineView, OsMesaFrameShowsAShadedMesenteryAPinkTubeAndTheCavity) {
  const Scene scene = shipped_intestine();
  IntestineView view(scene, scene.hash());
  auto renderer = make_renderer("osmesa", 320, 240);
  if (!renderer->gpu_skinning()) view.set_skinning(intestine::TubeSkinning::kCpu);
  const std::vector<double> x = rest_positions(scene);
  ASSERT_TRUE(view.set_positions(x.data(), static_cast<int>(x.size() / 3)));
  renderer->begin_frame(scene.visual.camera);
  view.draw(*renderer);
  renderer->end_frame();
  EXPECT_EQ(renderer->counts().surfaces, 2u);
  EXPECT_EQ(renderer->counts().rejected, 0u);
  EXPECT_EQ(renderer->counts().gl_errors, 0u);
  Image image;
  ASSERT_TRUE(renderer->read_image(image));
  int pink = 0, fat = 0, clear = 0, cavity = 0;
  std::vector<int> levels(766, 0);
  int lo = 765, hi = 0;
  for (int y = 0; y < image.height; ++y) {
    for (int px = 0; px < image.width; ++px) {
      const std::uint8_t* p = image.at(px, y);
      const int r = p[0], g = p[1], b = p[2];
      if (r == kBackgroundRgb[0] && g == kBackgroundRgb[1] && b == kBackgroundRgb[2]) ++clear;
      if (r + g + b < 120 && r > b + 3) ++cavity;
      if (r > 80 && r > g + 50 && r > b + 50) ++pink;
      if (r > 100 && g > r * 0.62 && g > b + 15) {  // the fat's hue: yellow-orange, not the tube's red
        ++fat;
        ++levels[static_cast<std::size_t>(r + g + b)];
        lo = std::min(lo, r + g + b);
        hi = std::max(hi, r + g + b);
      }
    }
  }
  const int n = image.width * image.height;
  int distinct = 0;
  for (const int c : levels) distinct += c > 0 ? 1 : 0;
  std::printf("intestine frame: %d pink, %d mesentery pixels (grey %d..%d, %d levels), %d clear, %d cavity of %d\n", pink,
              fat, lo, hi, distinct, clear, cavity, n);
  EXPECT_GT(pink, n / 50) << "the tube";
  EXPECT_GT(fat, n / 10) << "the mesentery";
  EXPECT_GT(hi - lo, 150) << "the mesentery is lit, not one flat colour";
  EXPECT_GT(distinct, 100) << "and smoothly shaded";
  EXPECT_EQ(clear, 0) << "the backdrop covers what the organ leaves";
  EXPECT_GT(cavity, n / 20) << "a dark red-brown cavity around the organ";
}

// The shipped camera looks like a laparoscope through the abdominal wall at the bowel, and nothing crosses
// right in front of the lens. For the rest shape and the shape it hangs in after 1.5 s under gravity (what the
// shipped runs show before the probe arrives), of the tube's vertices (CPU skinning, LOD 3): at least 70 % are in
// the picture (the loops fill the view; the ends along the root may leave it), their outline spans at least 60 % of
// the image's width and height, and none in the picture is nearer the lens, along the line of sight, than half the
// eye-target distance. The camera before (eye [0.25, 0.32, 0.18], fov 48) had the leg over the top of the vessel
// crossing the middle of the picture at 0.42 of that distance in the rest shape.
TEST(IntestineView, CameraSeesTheLoopsWithNothingRightInFrontOfTheLens) {
  const Scene scene = shipped_intestine();
  const Camera& camera = scene.visual.camera;
  const intestine::IntestineModel model(scene.intestine.params);
  intestine::IntestineState state(model);
  std::vector<std::vector<double>> shapes{rest_positions(scene)};
  intestine::StepReport report;
  const intestine::Probe none{};
  for (int s = 0; s < 1500; ++s) intestine::step(model, state, none, 1e-3, report);
  shapes.emplace_back(state.positions(), state.positions() + 3 * state.point_count());
  const Eigen::Vector3d forward = (camera.target - camera.eye).normalized();
  const double distance = (camera.target - camera.eye).norm();
  const int w = scene.visual.width, h = scene.visual.height;
  for (std::size_t k = 0; k < shapes.size(); ++k) {
    IntestineView view(scene, scene.hash(), intestine::TubeSkinning::kCpu);
    ASSERT_TRUE(view.set_positions(shapes[k].data(), static_cast<int>(shapes[k].size() / 3)));
    for (int i = 0; i < 8 && view.lod() != 3; ++i) {  // the controller down to LOD 3 (a frame 4x over its budget)
      view.frame_done(4.0 / scene.visual.target_fps);
      view.update();
    }
    ASSERT_TRUE(view.set_positions(shapes[k].data(), static_cast<int>(shapes[k].size() / 3)));
    int inside = 0;
    double nearest = std::numeric_limits<double>::infinity();
    Eigen::Vector2f lo(1e9f, 1e9f), hi(-1e9f, -1e9f);
    for (int v = 0; v < view.tube_vertices(); ++v) {
      const Eigen::Vector3f p = view.tube_positions().row(v).transpose();
      const double depth = (p.cast<double>() - camera.eye).dot(forward);
      const Eigen::Vector2f px = project_to_pixel(camera, w, h, p);
      if (depth <= 0 || px.x() < 0 || px.y() < 0 || px.x() > w || px.y() > h) continue;
      ++inside;
      nearest = std::min(nearest, depth);
      lo = lo.cwiseMin(px);
      hi = hi.cwiseMax(px);
    }
    const double share = static_cast<double>(inside) / view.tube_vertices();
    std::printf("%s (LOD %d): %.0f %% of the tube in the picture, spanning %.0f %% x %.0f %% of it, nearest %.3f m = "
                "%.2f of the eye-target distance\n", k == 0 ? "rest shape" : "hanging 1.5 s", view.lod(), 100 * share,
                100 * (hi.x() - lo.x()) / w, 100 * (hi.y() - lo.y()) / h, nearest, nearest / distance);
    EXPECT_GE(share, 0.7);
    EXPECT_GE((hi.x() - lo.x()) / w, 0.6f);
    EXPECT_GE((hi.y() - lo.y()) / h, 0.6f);
    EXPECT_GE(nearest, 0.5 * distance);
  }
}

}  // namespace
}  // namespace surgsim
