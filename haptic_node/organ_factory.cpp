// The one place the haptic node looks at the scene's model: adding an organ is one implementation and one line here.
#include "core/error.h"
#include "mesh/tri_surface.h"
#include "mesher/organ_overlap.h"
#include "mesher/scene_mesh.h"
#include "organ.h"
#include "organs/composite_organ.h"
#include "organs/intestine_organ.h"
#include "organs/liver_organ.h"
#include "organs/rigid_organ.h"

using namespace surgsim::core;
using namespace surgsim::scene;

namespace surgsim {

namespace {

// The organs' rest shapes (mesher/organ_overlap.h): none may lie inside another at rest by more than this.
constexpr double kRestOverlapTolerance = 1e-3;  // m

void check_organs_apart(const Scene& scene, const std::vector<CompositeOrgan::Part>& parts) {
  std::vector<mesher::RestShape> shapes;
  for (std::size_t k = 0; k < parts.size(); ++k) {
    const Scene one = scene.organ_scene(k);
    const std::string where = mesher::organ_where(one);
    const HapticOrgan* organ = parts[k].organ.get();
    if (const auto* liver = dynamic_cast<const LiverOrgan*>(organ)) {
      mesh::TriSurface boundary{liver->mesh().nodes, liver->surface().tris, where};
      mesh::compact_tri_surface(boundary);
      shapes.push_back(mesher::rest_shape_of_surface(boundary, false, parts[k].name, where));
    } else if (const auto* bowel = dynamic_cast<const IntestineOrgan*>(organ)) {
      const intestine::IntestineModel& m = bowel->model();
      std::vector<Eigen::Vector3d> line;
      for (int c = 0; c < m.columns(); ++c) line.emplace_back(m.rest().col(m.node(0, c)));
      shapes.push_back(mesher::rest_shape_of_tube(line, m.params().intestine_radius, parts[k].name, where));
    } else if (const auto* wall = dynamic_cast<const RigidOrgan*>(organ)) {
      shapes.push_back(
          mesher::rest_shape_of_surface(wall->surface().surface(), wall->surface().cavity(), parts[k].name, where));
      shapes.back().rigid = true;
    }
  }
  mesher::check_organs_apart(shapes, kRestOverlapTolerance);
}

}  // namespace

std::unique_ptr<HapticOrgan> make_haptic_organ(const Scene& scene, const std::string& cache_dir, std::uint64_t ticks,
                                               std::ostream* progress, const OrganBuildOptions& build) {
  if (scene.organ_list()) {
    // Every organ of the list, each built as its own one-organ scene in the scene's frame.
    std::vector<CompositeOrgan::Part> parts;
    for (std::size_t k = 0; k < scene.organs.size(); ++k) {
      const OrganSpec& o = scene.organs[k];
      if (o.model == "liver" && o.liver.deformation == compliance::LiverDeformation::kMultirate) {
        // Its view checks the tracker's BodyStates against a one-organ scene's identity; not in a field yet.
        throw_error(scene.file, ":", o.line, ": key '", o.key,
                    ".liver.deformation': multirate is not built into a scene with an organs: list yet (use linear "
                    "or corotational here, or the one-organ form of the scene for the multirate liver)");
      }
      if (progress != nullptr) {
        *progress << "organ " << k + 1 << "/" << scene.organs.size() << ": '" << o.name << "' (" << o.model << ")\n";
      }
      const Scene one = scene.organ_scene(k);
      std::unique_ptr<HapticOrgan> organ;
      if (o.model == "rigid") {
        organ = std::make_unique<RigidOrgan>(one);
      } else {
        organ = make_haptic_organ(one, cache_dir, ticks, progress, build);
      }
      parts.push_back({o.name, std::move(organ)});
    }
    check_organs_apart(scene, parts);
    return std::make_unique<CompositeOrgan>(std::move(parts));
  }
  if (scene.model == "liver") {
    return std::make_unique<LiverOrgan>(scene, cache_dir, progress, true, build.tracker_threads, build.unpaced);
  }
  // The mass-spring intestine and mesentery only: no mesh, tensors or bucket grid (docs/DESIGN.md, section 'Scenes').
  if (scene.model == "intestine") return std::make_unique<IntestineOrgan>(scene, ticks);
  throw_error(scene.file, ": key 'model': '", scene.model, "' is not built into this haptic node yet");
}

}  // namespace surgsim
