// multirate_view_bench: what drawing the multirate liver's shape costs the visual node, against the linear
// deformer it replaces, on the shipped config/liver_multirate.yaml:
//   - the wire: bytes of one serialized BodyState (XCDR1, encapsulation included) for the scene's boundary surface,
//     against header + 24 x surface nodes;
//   - the organ's update per frame (LiverView::update, us; wall and this thread's CPU): the linear deformer from a
//     fresh contact frame of a patch (u_n = sum_k G_nk lambda_k over every visible node) against a fresh BodyState
//     taken (LiverView::take_body_state: checks, positions, embedded surface) and the frame's update;
//   - the whole frame with OSMesa at the scene's size (update + draw + end_frame, ms) for both.
// Usage: multirate_view_bench [--frames N] [--scene S] [--no-render]. Percentiles of N frames per path.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <vector>

#include "bench_util.h"
#include "core/stats.h"
#include "mesher/scene_mesh.h"
#include "organ_view.h"
#include "render/renderer.h"
#include "scene/scene.h"
#include "surgsim_types.h"
#include "views/liver_view.h"

using namespace surgsim::core;
using namespace surgsim::compliance;
using namespace surgsim::scene;
using namespace surgsim::mesher;

namespace {

using namespace surgsim;

struct PathTimes {
  Percentiles wall_us, cpu_us, frame_ms;
};

void print_row(const char* name, const PathTimes& t, bool render) {
  std::printf("%-34s | %8.1f %8.1f %8.1f | %8.1f %8.1f", name, t.wall_us.p50, t.wall_us.p99, t.wall_us.max,
              t.cpu_us.p50, t.cpu_us.p99);
  if (render) std::printf(" | %7.2f %7.2f", t.frame_ms.p50, t.frame_ms.p99);
  std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 500;
  std::string scene_name = "liver_multirate";
  bool render = true;
  CLI::App cli{"multirate_view_bench: the visual node's cost of drawing the multirate liver's BodyState shape "
               "against the linear deformer (wire bytes, update per frame, OSMesa frame)"};
  cli.add_option("--frames", frames, "Frames per path (>= 20)")->check(CLI::Range(20, 1000000))->capture_default_str();
  cli.add_option("--scene", scene_name, "A liver scene with liver.deformation multirate")->capture_default_str();
  cli.add_flag("!--no-render", render, "Skip the OSMesa frame timings");
  CLI11_PARSE(cli, argc, argv);
  try {
    const Scene scene = load_scene(resolve_scene_path(scene_name));
    if (scene.liver.deformation != LiverDeformation::kMultirate) {
      std::fprintf(stderr, "multirate_view_bench: %s: liver.deformation is not multirate\n", scene.file.c_str());
      return 2;
    }
    OrganViewOptions oo;
    oo.cache_dir = default_cache_dir();
    LiverView view(scene, oo);
    const SurfaceDeformer& deformer = view.deformer();
    const int nodes = static_cast<int>(deformer.rest().rows());

    // The wire: one BodyState of this surface with one instrument, serialized as the writer sends it.
    msg::BodyStatePubSubType type;
    msg::BodyState sample;
    sample.positions().resize(static_cast<std::size_t>(nodes));
    sample.instruments().resize(scene.tools.size());
    const unsigned bytes = type.getSerializedSizeProvider(&sample)();
    std::printf("multirate_view_bench: %s, %d boundary surface nodes, %zu instrument(s), %d frames per path\n",
                scene.file.c_str(), nodes, scene.tools.size(), frames);
    std::printf("BodyState on the wire: %u bytes = %u header + 24 x %d positions (XCDR1, 4-byte encapsulation "
                "included); at the scene's visual rate %.0f Hz: %.2f MB/s at most\n",
                bytes, bytes - 24u * static_cast<unsigned>(nodes), nodes, scene.visual.rate_hz,
                bytes * scene.visual.rate_hz * 1e-6);

    // A patch contact as the haptic node sends it (20-30 nodes): the 25 visible nodes nearest a point above the
    // scene's tool (its trocar's x, y), 0.05 N down each.
    const Eigen::RowVector3f above(static_cast<float>(scene.tools[0].trocar.x()),
                                   static_cast<float>(scene.tools[0].trocar.y()), 0.1f);
    std::vector<std::pair<float, int>> nearest;
    for (int v = 0; v < nodes; ++v) nearest.emplace_back((deformer.rest().row(v) - above).norm(), v);
    std::sort(nearest.begin(), nearest.end());
    msg::ContactFrame frame;
    for (int k = 0; k < 25; ++k) {
      const int v = nearest[static_cast<std::size_t>(k)].second;
      msg::ContactEntry e;
      e.node(static_cast<std::uint32_t>(deformer.visible_nodes()[static_cast<std::size_t>(v)]));
      e.instrument(0);
      e.lambda().z(-0.05);
      frame.contacts().push_back(e);
    }
    msg::InstrumentState tool;
    tool.instrument(0);
    tool.direction().z(-1.0);
    frame.instruments().push_back(tool);

    // The shape: rest + a smooth lift of a few mm, changed a little every frame.
    std::vector<double> xyz(3 * static_cast<std::size_t>(nodes));
    const auto shape = [&](int f) {
      for (int v = 0; v < nodes; ++v) {
        const Eigen::Vector3f r = deformer.rest().row(v).transpose();
        xyz[3 * static_cast<std::size_t>(v)] = r.x();
        xyz[3 * static_cast<std::size_t>(v) + 1] = r.y();
        xyz[3 * static_cast<std::size_t>(v) + 2] = r.z() + 0.005 * (1 + 0.001 * f) * (0.13 - r.x());
      }
    };

    std::unique_ptr<Renderer> renderer;
    if (render) renderer = make_renderer("osmesa", scene.visual.width, scene.visual.height);
    const auto run = [&](bool body) {
      SampleRecorder wall(static_cast<std::size_t>(frames)), cpu(static_cast<std::size_t>(frames)),
          frame_ms(static_cast<std::size_t>(frames));
      for (int f = 0; f < frames; ++f) {
        if (body) shape(f);
        frame.contacts()[0].lambda().z(-0.05 - 1e-5 * f);  // every frame differs
        const auto t0 = bench::WallClock::now();
        const double c0 = bench::thread_cpu_us();
        if (body) view.take_body_state(xyz.data(), nodes, view.scene_hash(), 0, static_cast<std::uint64_t>(f + 1));
        view.update(&frame, true);
        cpu.add(bench::thread_cpu_us() - c0);
        wall.add(bench::us_since(t0));
        if (renderer != nullptr) {
          renderer->begin_frame(scene.visual.camera);
          view.draw(*renderer);
          view.draw_markers(*renderer);
          renderer->end_frame();
          frame_ms.add(bench::us_since(t0) * 1e-3);
        }
      }
      return PathTimes{wall.summary(), cpu.summary(), frame_ms.summary()};
    };
    // The linear deformer first (the view draws it until its first BodyState), then the shape path.
    const PathTimes linear = run(false);
    const PathTimes shape_path = run(true);
    std::printf("\nOrgan update per frame (us: LiverView::update, with take_body_state for the shape)%s\n",
                render ? "; whole frame with OSMesa (ms: update + draw + end_frame)" : "");
    std::printf("%-34s | %8s %8s %8s | %8s %8s", "path", "wall p50", "p99", "max", "cpu p50", "p99");
    if (render) std::printf(" | %7s %7s", "frame50", "frame99");
    std::printf("\n");
    char name[64];
    std::snprintf(name, sizeof name, "linear deformer, %zu contacts", frame.contacts().size());
    print_row(name, linear, render);
    print_row("BodyState shape (multirate)", shape_path, render);
    std::printf("contact frames not applied: %llu (must be 0)\n", static_cast<unsigned long long>(view.deform_errors()));
    std::printf(
        "budget (docs/DESIGN.md, section 'Budgets'): deformation of the visible mesh <= 1000 us; "
        "frames >= 50 Hz (20 ms) at 640x480\n");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "multirate_view_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
