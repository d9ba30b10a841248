// The organ mesh a scene names: read from its file, or generated (and cached) by the organ mesher.
#pragma once
#include <iosfwd>
#include <string>

#include "mesh/mesh.h"
#include "scene/scene.h"

namespace surgsim::mesher {

/// Cache folder for generated meshes and tensors: $SURGSIM_CACHE_DIR, else $XDG_CACHE_HOME/surgsim,
/// else ~/.cache/surgsim. Created if missing.
std::string default_cache_dir();

/// Loads (file) or generates-and-caches (generate) the scene's tetrahedral mesh and validates it. A cached mesh that
/// ensure_organ_mesh refused (damaged, or of another generator) is said on `progress` with the reason. The mesh is
/// returned in the scene's frame: moved by scene.placement (an organ_scene() of an `organs:` list).
/// Throws surgsim::core::Error naming the scene file and the mesh at fault.
mesh::TetMesh load_scene_mesh(const scene::Scene& scene, const std::string& cache_dir,
                              std::ostream* progress = nullptr);

}  // namespace surgsim::mesher
