#include "organ_view.h"

#include <initializer_list>

#include "core/error.h"
#include "mesher/scene_mesh.h"
#include "views/composite_view.h"
#include "views/intestine_view.h"
#include "views/liver_view.h"
#include "views/rigid_view.h"

using namespace surgsim::mesh;
using namespace surgsim::scene;

namespace surgsim {

namespace {
bool named(const std::string& name, std::initializer_list<const char*> words) {
  for (const char* w : words) {
    if (name.find(w) != std::string::npos) return true;
  }
  return false;
}
}  // namespace

Eigen::Vector3f organ_rgb(const OrganSpec& organ) {
  if (organ.has_colour) return organ.colour.cast<float>();
  if (organ.model == "liver") return kLiverRgb;
  if (organ.model == "intestine") return kIntestineRgb;
  if (organ_is_bone(organ)) return {0.88f, 0.85f, 0.76f};
  if (organ.rigid.generate == "plane" || named(organ.name, {"floor", "retroperitoneum", "back"})) {
    return {0.62f, 0.32f, 0.30f};
  }
  return {0.76f, 0.42f, 0.40f};  // the abdominal wall's parietal peritoneum
}

bool organ_is_bone(const OrganSpec& organ) {
  if (organ.model != "rigid") return false;
  const std::string& g = organ.rigid.generate;
  return g == "ribs" || g == "tube" || g == "box" || named(organ.name, {"rib", "bone", "spine", "pelvis"});
}

std::uint64_t visual_scene_hash(const Scene& scene, std::uint64_t mesh_hash) {
  return scene.hash() ^ (mesh_hash * 0x9E3779B97F4A7C15ull);
}

std::unique_ptr<OrganView> make_organ_view(const Scene& scene, const OrganViewOptions& options) {
  if (scene.organ_list()) {
    // Every organ of the list, each as its own one-organ scene in the scene's frame. The intestine checks its
    // BodyStates against the whole scene's identity, which needs every other organ's mesh hash first: built last.
    std::vector<CompositeView::Part> parts(scene.organs.size());
    std::vector<std::uint64_t> hashes(scene.organs.size(), 0);
    for (std::size_t k = 0; k < scene.organs.size(); ++k) {
      const OrganSpec& o = scene.organs[k];
      if (o.model == "intestine") continue;
      if (options.log != nullptr) {
        *options.log << "organ " << k + 1 << "/" << scene.organs.size() << ": '" << o.name << "' (" << o.model << ")\n";
      }
      const Scene one = scene.organ_scene(k);
      OrganViewOptions part = options;
      part.organ_index = static_cast<int>(k);  // the contact entries and BodyStates it draws (wire v3)
      parts[k].name = o.name;
      parts[k].view = o.model == "rigid" ? std::unique_ptr<OrganView>(std::make_unique<RigidView>(one))
                                         : make_organ_view(one, part);
      hashes[k] = parts[k].view->mesh_hash();
    }
    const std::uint64_t whole = visual_scene_hash(scene, mesher::combine_organ_hashes(hashes));
    for (std::size_t k = 0; k < scene.organs.size(); ++k) {
      const OrganSpec& o = scene.organs[k];
      if (o.model != "intestine") continue;
      parts[k].name = o.name;
      parts[k].view =
          std::make_unique<IntestineOrganView>(scene.organ_scene(k), whole, options.tube_skinning, static_cast<int>(k));
    }
    auto composite = std::make_unique<CompositeView>(std::move(parts));
    composite->order_for(scene.visual.camera.eye);
    return composite;
  }
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
