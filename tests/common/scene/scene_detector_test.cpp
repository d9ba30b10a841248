// intestine.detector: the scene chooses the self-collision detector the haptic step runs; the stochastic
// one by default, the exact broad phase on request; a bad value names the key and the choices; it enters the hash.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "core/error.h"
#include "scene/scene.h"

using namespace surgsim::core;
using namespace surgsim::scene;

namespace surgsim {
namespace {

namespace fs = std::filesystem;

std::string write_scene(const std::string& name, const std::string& text) {
  const fs::path dir = fs::path(::testing::TempDir()) / "scene_detector_test";
  fs::create_directories(dir);
  const fs::path path = dir / name;
  std::ofstream(path, std::ios::binary) << text;
  return path.string();
}

const std::string kBase = "name: gut\nmodel: intestine\n";

TEST(SceneDetector, StochasticByDefaultBroadPhaseOnRequest) {
  EXPECT_EQ(load_scene(write_scene("a.yaml", kBase)).intestine.params.detector,
            intestine::CollisionDetector::kStochastic);
  EXPECT_EQ(load_scene(write_scene("b.yaml", kBase + "intestine: {columns: 100}\n")).intestine.params.detector,
            intestine::CollisionDetector::kStochastic);
  EXPECT_EQ(load_scene(write_scene("c.yaml", kBase + "intestine: {detector: stochastic}\n")).intestine.params.detector,
            intestine::CollisionDetector::kStochastic);
  EXPECT_EQ(load_scene(write_scene("d.yaml", kBase + "intestine: {detector: broad_phase}\n")).intestine.params.detector,
            intestine::CollisionDetector::kBroadPhase);
}

TEST(SceneDetector, EntersTheHash) {
  const std::uint64_t h0 = load_scene(write_scene("e.yaml", kBase)).hash();
  EXPECT_EQ(h0, load_scene(write_scene("f.yaml", kBase + "intestine: {detector: stochastic}\n")).hash());
  EXPECT_NE(h0, load_scene(write_scene("g.yaml", kBase + "intestine: {detector: broad_phase}\n")).hash());
}

TEST(SceneDetector, UnknownDetectorNamesTheKeyLineAndChoices) {
  const std::string path = write_scene("h.yaml", kBase + "intestine:\n  detector: sweep\n");
  std::string msg;
  try {
    load_scene(path);
  } catch (const Error& e) {
    msg = e.what();
  }
  EXPECT_NE(msg.find("h.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find(":4"), std::string::npos) << msg;
  EXPECT_NE(msg.find("intestine.detector"), std::string::npos) << msg;
  EXPECT_NE(msg.find("broad_phase, stochastic"), std::string::npos) << msg;
  EXPECT_NE(msg.find("sweep"), std::string::npos) << msg;
}

}  // namespace
}  // namespace surgsim
