// The one place the haptic node looks at the scene's model: adding an organ is one implementation and one line here.
#include "core/error.h"
#include "organ.h"
#include "organs/intestine_organ.h"
#include "organs/liver_organ.h"

using namespace surgsim::core;
using namespace surgsim::scene;

namespace surgsim {

std::unique_ptr<HapticOrgan> make_haptic_organ(const Scene& scene, const std::string& cache_dir, std::uint64_t ticks,
                                               std::ostream* progress, const OrganBuildOptions& build) {
  if (scene.model == "liver") {
    return std::make_unique<LiverOrgan>(scene, cache_dir, progress, true, build.tracker_threads, build.unpaced);
  }
  // The mass-spring intestine and mesentery only: no mesh, tensors or bucket grid (docs/DESIGN.md, section 'Scenes').
  if (scene.model == "intestine") return std::make_unique<IntestineOrgan>(scene, ticks);
  throw_error(scene.file, ": key 'model': '", scene.model, "' is not built into this haptic node yet");
}

}  // namespace surgsim
