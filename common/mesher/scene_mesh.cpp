#include "mesher/scene_mesh.h"

#include <cstdlib>
#include <filesystem>
#include <ostream>

#include "core/error.h"
#include "mesher/organ_mesher.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::scene;

namespace surgsim::mesher {

std::string default_cache_dir() {
  std::string dir;
  if (const char* env = std::getenv("SURGSIM_CACHE_DIR"); env != nullptr && *env != '\0') {
    dir = env;
  } else if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg != nullptr && *xdg != '\0') {
    dir = std::string(xdg) + "/surgsim";
  } else if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0') {
    dir = std::string(home) + "/.cache/surgsim";
  } else {
    dir = "/tmp/surgsim-cache";
  }
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw_error(dir, ": cannot create the cache folder (", ec.message(), "); set SURGSIM_CACHE_DIR or --cache");
  return dir;
}

TetMesh load_scene_mesh(const Scene& scene, const std::string& cache_dir, std::ostream* progress) {
  std::string path = scene.mesh.file;
  if (path.empty()) {
    OrganSpec spec;
    spec.shape = scene.mesh.generate;
    spec.target_nodes = scene.mesh.target_nodes;
    if (progress != nullptr) *progress << "mesh: " << spec.shape << " ~" << spec.target_nodes << " nodes (cache " << cache_dir << ")\n";
    OrganMeshCacheOutcome outcome;
    path = ensure_organ_mesh(spec, cache_dir, nullptr, &outcome);
    if (progress != nullptr && !outcome.rejected.empty())
      *progress << "mesh: the cached " << path << " was not used (" << outcome.rejected << "); generated it again\n";
  }
  try {
    TetMesh mesh = read_mesh(path);
    validate_mesh(mesh);
    // A placed organ (an entry of an `organs:` list): its mesh in the scene's frame. A rigid motion keeps the mesh
    // valid and its tets positively oriented; the tensors are computed on the placed mesh (its hash keys them).
    if (!scene.placement.identity()) {
      mesh.nodes = (mesh.nodes * scene.placement.rotation.transpose()).rowwise() +
                   scene.placement.translation.transpose();
    }
    return mesh;
  } catch (const Error& e) {
    throw_error(scene.file, ": mesh of scene '", scene.name, "': ", e.what());
  }
}

}  // namespace surgsim::mesher
