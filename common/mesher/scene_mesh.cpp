#include "mesher/scene_mesh.h"

#include <cstdlib>
#include <filesystem>
#include <ostream>

#include "core/error.h"
#include "core/hash.h"
#include "mesher/organ_mesher.h"
#include "rigid/rigid_shapes.h"

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

std::string organ_where(const Scene& scene) {
  const scene::OrganSpec& o = scene.organs.at(0);
  return scene.file + ":" + std::to_string(o.line) + ": organ '" + o.name + "'" +
         (o.key.empty() ? std::string() : " (key '" + o.key + "')");
}

mesh::TriSurface load_scene_surface(const Scene& scene) {
  const scene::RigidSpec& g = scene.rigid;
  mesh::TriSurface local;
  try {
    if (!g.file.empty()) {
      local = mesh::read_obj(g.file);
    } else if (g.generate == "plane") {
      local = rigid::plane_patch(g.size.x(), g.size.y(), 16);
    } else if (g.generate == "box") {
      local = rigid::box_surface(g.size / 2, 8);
    } else if (g.generate == "tube") {
      local = rigid::tube_surface(g.size.x(), g.size.y(), 32, 16, true);
    } else if (g.generate == "dome") {
      local = rigid::ellipsoid_shell(g.size, 96, 48, g.dome_open_z);
    } else if (g.generate == "ribs") {
      rigid::RibsSpec ribs;
      ribs.count = g.count;
      ribs.arc_radius = g.size.x();
      ribs.spacing = g.size.y();
      ribs.tube_radius = g.size.z();
      ribs.arc_deg = g.arc_deg;
      local = rigid::ribs(ribs);
    } else {
      throw_error("no surface: neither a file nor a known generator ('", g.generate, "')");
    }
  } catch (const Error& e) {
    throw_error(organ_where(scene), ": rigid surface: ", e.what());
  }
  return rigid::placed(local, scene.placement);
}

std::uint64_t rigid_surface_hash(const mesh::TriSurface& s, bool cavity) {
  core::Hasher h;
  h.str("rigid-surface");
  h.value<std::uint8_t>(cavity);
  h.value<std::int64_t>(s.vertices.rows());
  h.value<std::int64_t>(s.tris.rows());
  for (Eigen::Index i = 0; i < s.vertices.rows(); ++i) {
    for (int k = 0; k < 3; ++k) h.value<double>(s.vertices(i, k));
  }
  for (Eigen::Index i = 0; i < s.tris.rows(); ++i) {
    for (int k = 0; k < 3; ++k) h.value<std::int32_t>(s.tris(i, k));
  }
  return h.digest();
}

std::uint64_t combine_organ_hashes(const std::vector<std::uint64_t>& hashes) {
  core::Hasher h;
  h.str("organs");
  for (std::uint64_t v : hashes) h.value<std::uint64_t>(v);
  return h.digest();
}

}  // namespace surgsim::mesher
