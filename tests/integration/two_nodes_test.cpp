// Both real nodes as processes on one host over Fast DDS: frames arrive, PNGs with the organ are written,
// stats files have the keys of docs/DESIGN.md, section 'Programs and their stable interface'.
#include <fcntl.h>
#include <png.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <filesystem>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "png_rgb.h"
#include "node_test.h"
#include "process.h"

namespace surgsim {
namespace {

namespace fs = std::filesystem;
using testing::Process;

using testing::Rgb;
using testing::read_png_rgb;

class TwoNodes : public testing::NodeTest {
 protected:
  void SetUp() override { prepare("two_nodes", 0); }
};

TEST_F(TwoNodes, FramesArriveAndOrganIsRendered) {
  const std::string frames = (dir_ / "frames").string();
  Process visual(bin("visual_node"),
                 {"--scene", "liver", "--out", frames, "--stats", (dir_ / "visual.json").string(), "--png-every", "10"},
                 env_, (dir_ / "visual.log").string());
  Process haptic(bin("haptic_node"),
                 {"--scene", "liver", "--wait-for-visual", "60", "--rt-priority", "0",
                  "--stats", (dir_ / "haptic.json").string()},
                 env_, (dir_ / "haptic.log").string());
  ASSERT_EQ(haptic.wait(240), 0) << testing::read_file((dir_ / "haptic.log").string());
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  visual.signal(SIGINT);
  ASSERT_EQ(visual.wait(60), 0) << testing::read_file((dir_ / "visual.log").string());

  // Haptic stats: every tick of the run, the keys of docs/DESIGN.md, section 'Programs and their stable interface'.
  const auto h = nlohmann::json::parse(testing::read_file((dir_ / "haptic.json").string()));
  for (const char* key : {"rate_hz", "ticks", "achieved_hz", "tick_us", "deadline_misses", "contacts_max",
                          "force_max_n", "nonfinite_rejected"}) {
    EXPECT_TRUE(h.contains(key)) << key;
  }
  // The default poke (4 s) plus 0.5 s of hold.
  EXPECT_EQ(h["ticks"].get<int>(), static_cast<int>(4.5 * h["rate_hz"].get<double>() + 0.5));
  EXPECT_GT(h["contacts_max"].get<int>(), 0);
  EXPECT_GT(h["force_max_n"].get<double>(), 0.1);
  EXPECT_EQ(h["nonfinite_rejected"].get<int>(), 0);

  // Visual stats: frames arrived from the other process and the scene identity matched.
  const auto v = nlohmann::json::parse(testing::read_file((dir_ / "visual.json").string()));
  for (const char* key : {"frames_received", "frames_rendered", "fps", "deform_us", "render_ms", "latency_us",
                          "scene_hash_ok"}) {
    EXPECT_TRUE(v.contains(key)) << key;
  }
  EXPECT_GT(v["frames_received"].get<int>(), 50);
  EXPECT_GT(v["frames_rendered"].get<int>(), 10);
  EXPECT_TRUE(v["scene_hash_ok"].get<bool>());
  EXPECT_GT(v["latency_us"]["count"].get<int>(), 50);

  // The frame index: the organ is dented while the tool presses, and back at rest after release.
  std::ifstream index(frames + "/frames.csv");
  std::string line;
  std::getline(index, line);
  double max_pressed = 0, last_released = -1, last_time = 0;
  int pressed_frames = 0;
  while (std::getline(index, line)) {
    std::stringstream ss(line);
    std::string png, seq, t, contacts, u;
    std::getline(ss, png, ',');
    std::getline(ss, seq, ',');
    std::getline(ss, t, ',');
    std::getline(ss, contacts, ',');
    std::getline(ss, u, ',');
    ASSERT_TRUE(fs::exists(frames + "/" + png)) << png;
    const double time = std::stod(t), disp = std::stod(u);
    if (std::stoi(contacts) > 0) {
      ++pressed_frames;
      max_pressed = std::max(max_pressed, disp);
    } else if (time > 3.0) {
      last_released = disp;  // after the tool has come back out
    }
    last_time = time;
  }
  EXPECT_GT(pressed_frames, 5);
  EXPECT_GT(max_pressed, 0.005) << "a visible dent (m) while the tool presses";
  EXPECT_EQ(last_released, 0.0) << "the rest shape after release";
  EXPECT_GT(last_time, 3.0);

  // A PNG with the organ in it: a good share of reddish organ pixels, not a blank frame.
  std::vector<fs::path> pngs;
  for (const auto& e : fs::directory_iterator(frames)) {
    if (e.path().extension() == ".png") pngs.push_back(e.path());
  }
  ASSERT_FALSE(pngs.empty());
  std::sort(pngs.begin(), pngs.end());
  const Rgb img = read_png_rgb(pngs.back().string());
  ASSERT_FALSE(img.data.empty()) << pngs.back();
  long organ = 0;
  const long n = static_cast<long>(img.width) * img.height;
  for (long i = 0; i < n; ++i) {
    const int r = img.data[3 * i], g = img.data[3 * i + 1], b = img.data[3 * i + 2];
    if (r > 60 && r > g + 25 && r > b + 25) ++organ;
  }
  EXPECT_GT(organ, n / 20) << "too few organ-coloured pixels in " << pngs.back();
}

TEST_F(TwoNodes, VisualRefusesAnotherScene) {
  Process visual(bin("visual_node"),
                 {"--scene", "plate", "--headless", "--stats", (dir_ / "visual.json").string()},
                 env_, (dir_ / "visual.log").string());
  Process haptic(bin("haptic_node"),
                 {"--scene", "liver", "--duration", "1.0", "--wait-for-visual", "60", "--rt-priority", "0",
                  "--speed", "1"},
                 env_, (dir_ / "haptic.log").string());
  ASSERT_EQ(haptic.wait(240), 0) << testing::read_file((dir_ / "haptic.log").string());
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  visual.signal(SIGINT);
  EXPECT_EQ(visual.wait(60), 3);
  const std::string log = testing::read_file((dir_ / "visual.log").string());
  EXPECT_NE(log.find("the haptic node runs scene 'liver'"), std::string::npos) << log;
  const auto v = nlohmann::json::parse(testing::read_file((dir_ / "visual.json").string()));
  EXPECT_FALSE(v["scene_hash_ok"].get<bool>());
}

TEST(NodeCli, HelpAndBadArguments) {
  for (const char* node : {"haptic_node", "visual_node"}) {
    const std::string b = std::string(SURGSIM_TEST_BIN_DIR) + "/" + node;
    const std::string log = ::testing::TempDir() + "/cli_" + node + ".log";
    {
      Process p(b, {"--help"}, {}, log);
      EXPECT_EQ(p.wait(30), 0) << node;
      EXPECT_NE(testing::read_file(log).find("--scene"), std::string::npos);
    }
    {
      Process p(b, {"--scene", "/nonexistent/scene.yaml"}, {"SURGSIM_CONFIG_DIR=" SURGSIM_TEST_CONFIG_DIR}, log);
      EXPECT_EQ(p.wait(30), 1) << node;
      EXPECT_NE(testing::read_file(log).find("/nonexistent/scene.yaml"), std::string::npos) << testing::read_file(log);
    }
  }
}

}  // namespace
}  // namespace surgsim
