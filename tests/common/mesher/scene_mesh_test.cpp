// Tests for common/mesher/scene_mesh.cpp: a scene's generated mesh comes from the cache, and a damaged cached mesh is
// said on the progress stream and generated again.
#include "mesher/scene_mesh.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <sstream>
#include <string>

#include "mesher/organ_mesher.h"

using namespace surgsim::mesh;
using namespace surgsim::mesher;

namespace surgsim {
namespace {

TEST(SceneMesh, DamagedCachedMeshIsSaidAndGeneratedAgain) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("surgsim_scene_mesh_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  scene::Scene s;
  s.name = "cylinder";
  s.file = (dir / "cylinder.yaml").string();
  s.mesh.generate = "cylinder";
  s.mesh.target_nodes = 500;
  const TetMesh first = load_scene_mesh(s, dir.string());
  const std::string path = organ_mesh_path(OrganSpec{"cylinder", 500}, dir.string());
  ASSERT_TRUE(fs::is_regular_file(path));

  fs::resize_file(path, fs::file_size(path) - 10);  // cut short
  std::ostringstream log;
  const TetMesh again = load_scene_mesh(s, dir.string(), &log);
  EXPECT_NE(log.str().find("the cached " + path + " was not used"), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("generated it again"), std::string::npos) << log.str();
  EXPECT_EQ(mesh_hash(again), mesh_hash(first));

  std::ostringstream quiet;
  load_scene_mesh(s, dir.string(), &quiet);
  EXPECT_EQ(quiet.str().find("not used"), std::string::npos) << quiet.str();
  fs::remove_all(dir);
}

}  // namespace
}  // namespace surgsim
