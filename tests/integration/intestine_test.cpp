// The intestine scene with both real nodes as processes over Fast DDS: the haptic node steps the
// mass-spring intestine with the tool tip as the probe and publishes BodyState, the visual node draws the skinned tube
// and the mesentery; and a liver run of both nodes builds no intestine objects.
#include <png.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <sstream>

#include "png_rgb.h"
#include "node_test.h"
#include "process.h"

namespace surgsim {
namespace {

namespace fs = std::filesystem;
using testing::Process;

using testing::Rgb;
using testing::read_png_rgb;

class IntestineNodes : public testing::NodeTest {
 protected:
  void SetUp() override { prepare("intestine", 3); }
  nlohmann::json stats(const char* name) const { return json(path(name)); }
};

// The push trajectory up to t = 4 s: the folds settle (0.5 s), the tip enters them at about 1.9 s and pushes 1-2 N.
TEST_F(IntestineNodes, PushIsSimulatedPublishedAndDrawn) {
  const std::string frames = (dir_ / "frames").string();
  Process visual(bin("visual_node"),
                 {"--scene", "intestine", "--out", frames, "--stats", (dir_ / "visual.json").string(), "--png-every",
                  "10"},
                 env_, (dir_ / "visual.log").string());
  Process haptic(bin("haptic_node"),
                 {"--scene", "intestine", "--replay", SURGSIM_TEST_CONFIG_DIR "/trajectories/intestine_push.csv",
                  "--duration", "4", "--wait-for-visual", "60", "--rt-priority", "0", "--no-mlock", "--stats",
                  (dir_ / "haptic.json").string(), "--log", (dir_ / "haptic.csv").string()},
                 env_, (dir_ / "haptic.log").string());
  ASSERT_EQ(haptic.wait(120), 0) << testing::read_file((dir_ / "haptic.log").string());
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  visual.signal(SIGINT);
  ASSERT_EQ(visual.wait(60), 0) << testing::read_file((dir_ / "visual.log").string());

  // Haptic: only the intestine was built; every tick stepped it and published a BodyState; no fault.
  const auto h = stats("haptic.json");
  EXPECT_EQ(h["model_built"], "intestine");
  EXPECT_EQ(h["tensor_hash"], "0");
  const int ticks = h["ticks"].get<int>();
  EXPECT_EQ(ticks, static_cast<int>(4 * h["rate_hz"].get<double>() + 0.5));
  const auto& in = h["intestine"];
  EXPECT_EQ(in["nodes"].get<int>(), 400);
  EXPECT_EQ(in["steps"].get<int>(), ticks);
  EXPECT_EQ(in["body_states_published"].get<int>(), ticks);
  EXPECT_EQ(in["faults"].get<int>(), 0);
  EXPECT_TRUE(in["positions_finite"].get<bool>());
  EXPECT_TRUE(in["energy_j"].is_number());
  EXPECT_GT(in["self_contacts_max"].get<int>(), 0) << "the folds lie on each other";
  EXPECT_GT(in["step_us"]["p50"].get<double>(), 0.0);
  EXPECT_GT(in["probe_contacts_max"].get<int>(), 0);
  EXPECT_GT(h["contacts_max"].get<int>(), 0);
  EXPECT_EQ(h["nonfinite_rejected"].get<int>(), 0);
  EXPECT_GT(h["force_max_n"].get<double>(), 0.3);
  EXPECT_LE(h["force_max_n"].get<double>(), 8.0 + 1e-9);  // the tool's force limit

  // The per-tick log: finite everywhere, zero force before the tip reaches the folds, a force while it pushes.
  std::ifstream log((dir_ / "haptic.csv").string());
  std::string line;
  std::getline(log, line);
  int rows = 0, pushing = 0, pushing_with_force = 0;
  double force_before = 0;
  while (std::getline(log, line)) {
    std::stringstream ss(line);
    std::string cell[6];
    for (auto& c : cell) std::getline(ss, c, ',');
    const double t = std::stod(cell[1]);
    const double f = std::hypot(std::stod(cell[2]), std::stod(cell[3]), std::stod(cell[4]));
    ASSERT_TRUE(std::isfinite(f) && std::isfinite(t)) << line;
    ++rows;
    if (t < 1.0) force_before = std::max(force_before, f);
    if (t >= 2.0 && t <= 3.8) {
      ++pushing;
      if (f > 0.05) ++pushing_with_force;
    }
  }
  EXPECT_EQ(rows, ticks);
  EXPECT_EQ(force_before, 0.0) << "no force while the tip is away from the folds";
  ASSERT_GT(pushing, 0);
  EXPECT_GT(pushing_with_force, pushing / 2) << "the probe pushes the folds";

  // Visual: BodyStates arrived and were drawn, the LOD controller ran, the scene identity matched.
  const auto v = stats("visual.json");
  EXPECT_EQ(v["model_built"], "intestine");
  EXPECT_TRUE(v["scene_hash_ok"].get<bool>());
  EXPECT_EQ(v["tensor_rows"].get<int>(), 0);
  EXPECT_GT(v["frames_rendered"].get<int>(), 20);
  EXPECT_GT(v["frames_received"].get<int>(), 50);  // the ContactFrames (latency and echo paths)
  const auto& vi = v["intestine"];
  EXPECT_GT(vi["body_states_received"].get<int>(), 50);
  EXPECT_GT(vi["body_states_shown"].get<int>(), 20);
  EXPECT_EQ(vi["body_states_rejected"].get<int>(), 0);
  EXPECT_EQ(vi["build_failures"].get<int>(), 0);
  EXPECT_GT(vi["tube_triangles_max"].get<int>(), 1000);
  EXPECT_GT(vi["target_fps"].get<double>(), 0.0);
  EXPECT_GE(vi["lod_mean"].get<double>(), 0.0);
  EXPECT_LE(vi["lod_mean"].get<double>(), 6.0);
  long lod_frames = 0;
  for (const auto& n : vi["lod_histogram"]) lod_frames += n.get<long>();
  EXPECT_GT(lod_frames, 20);

  // The last PNG shows the intestine: many pink tube pixels and a good share of foreground, not a blank frame.
  std::vector<fs::path> pngs;
  for (const auto& e : fs::directory_iterator(frames)) {
    if (e.path().extension() == ".png") pngs.push_back(e.path());
  }
  ASSERT_FALSE(pngs.empty());
  std::sort(pngs.begin(), pngs.end());
  const Rgb img = read_png_rgb(pngs.back().string());
  ASSERT_FALSE(img.data.empty()) << pngs.back();
  long pink = 0, foreground = 0;
  const long n = static_cast<long>(img.width) * img.height;
  for (long i = 0; i < n; ++i) {
    const int r = img.data[3 * i], g = img.data[3 * i + 1], b = img.data[3 * i + 2];
    if (std::abs(r - 40) + std::abs(g - 42) + std::abs(b - 48) > 30) ++foreground;
    if (r > 80 && r > g + 40 && r > b + 40) ++pink;
  }
  EXPECT_GT(foreground, n / 8) << pngs.back();
  EXPECT_GT(pink, n / 40) << "too few intestine-coloured pixels in " << pngs.back();
}

// A liver run builds the liver only: the stats of both nodes name it, and carry no intestine section.
TEST_F(IntestineNodes, LiverRunBuildsNoIntestine) {
  Process visual(bin("visual_node"),
                 {"--scene", "liver", "--headless", "--duration", "1.5", "--stats", (dir_ / "visual.json").string()},
                 env_, (dir_ / "visual.log").string());
  Process haptic(bin("haptic_node"),
                 {"--scene", "liver", "--duration", "0.5", "--speed", "max", "--rt-priority", "0", "--no-mlock",
                  "--stats", (dir_ / "haptic.json").string()},
                 env_, (dir_ / "haptic.log").string());
  ASSERT_EQ(haptic.wait(240), 0) << testing::read_file((dir_ / "haptic.log").string());
  ASSERT_EQ(visual.wait(240), 0) << testing::read_file((dir_ / "visual.log").string());
  const auto h = stats("haptic.json");
  const auto v = stats("visual.json");
  EXPECT_EQ(h["model_built"], "liver");
  EXPECT_EQ(v["model_built"], "liver");
  EXPECT_FALSE(h.contains("intestine"));
  EXPECT_FALSE(v.contains("intestine"));
  EXPECT_NE(h["tensor_hash"], "0");
  EXPECT_GT(v["tensor_rows"].get<int>(), 0);
}

}  // namespace
}  // namespace surgsim
