// The organ mesh a scene names: read from its file, or generated (and cached) by the organ mesher.
#pragma once
#include <iosfwd>
#include <cstdint>
#include <string>
#include <vector>

#include "mesh/mesh.h"
#include "mesh/tri_surface.h"
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

/// The surface of a rigid organ (scene.rigid of an organ_scene()): read from its .obj file or generated, in the
/// scene's frame (moved by scene.placement). Both nodes build it the same way. Throws surgsim::core::Error naming the
/// scene file, the organ's line and key.
mesh::TriSurface load_scene_surface(const scene::Scene& scene);

/// Identity of a rigid organ's surface (its vertices, triangles and free side), as both nodes mix it into the scene
/// identity they compare.
std::uint64_t rigid_surface_hash(const mesh::TriSurface& surface, bool cavity);

/// Where a message about organ_scene `scene`'s organ points: "FILE:LINE: organ 'NAME' (key 'KEY')".
std::string organ_where(const scene::Scene& scene);

/// The identity of several organs together (their mesh or surface hashes, in the scene's order), as both nodes
/// compute it for a scene with an `organs:` list.
std::uint64_t combine_organ_hashes(const std::vector<std::uint64_t>& hashes);

}  // namespace surgsim::mesher
