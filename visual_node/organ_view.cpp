#include "organ_view.h"

#include "views/intestine_view.h"
#include "views/liver_view.h"
#include "core/error.h"

using namespace surgsim::mesh;
using namespace surgsim::scene;

namespace surgsim {

std::uint64_t visual_scene_hash(const Scene& scene, std::uint64_t mesh_hash) {
  return scene.hash() ^ (mesh_hash * 0x9E3779B97F4A7C15ull);
}

std::unique_ptr<OrganView> make_organ_view(const Scene& scene, const OrganViewOptions& options) {
  // The intestine: a skinned tube and the mesentery from BodyStates; no tetrahedral mesh (hash 0, as in the haptic
  // node), no tensors, no deformer.
  if (scene.model == "intestine") {
    return std::make_unique<IntestineOrganView>(scene, visual_scene_hash(scene, 0), options.tube_skinning,
                                                options.organ_index);
  }
  if (scene.model == "liver") return std::make_unique<LiverView>(scene, options);
  // An organ this node cannot draw is refused, as the haptic node refuses one it cannot simulate (it used to be drawn
  // as a liver).
  core::throw_error(scene.file, ": key 'model': '", scene.model, "' is not built into this visual node yet");
}

}  // namespace surgsim
