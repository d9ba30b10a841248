// tube_skinning_bench: frame time of the intestine tube with GPU skinning (the vertex shader blends the primitive
// with the per-interval matrices: Renderer::draw_skinned_tube) against CPU skinning (TubeBuilder writes the vertices,
// the renderer uploads them and recomputes normals: draw_surface), per level of detail, in the OSMesa renderer at
// the intestine scene's size and camera. Prints a table; run by hand (not a ctest):
//   build/bench/tube_skinning_bench [--frames N] [--scene NAME|FILE]
// Each frame moves the folded rest shape a little (so every frame rebuilds the tube) and times build + draw +
// end_frame (the renderer waits for llvmpipe) on the wall clock (llvmpipe shades on its own threads, so this
// thread's CPU time would miss most of it). The two paths alternate frame by frame, so both see the same load.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "intestine/intestine_model.h"
#include "render/renderer.h"
#include "intestine/tube_geometry.h"

using namespace surgsim::intestine;
using namespace surgsim::scene;

namespace {

using namespace surgsim;
using namespace surgsim::intestine;
using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

double pct(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

struct Timing {
  std::vector<double> build_ms, frame_ms;
};

}  // namespace

int main(int argc, char** argv) {
  int frames = 60;
  std::string scene_file = "intestine";
  CLI::App cli{"Frame time of the intestine tube, GPU (vertex shader) against CPU skinning, per LOD (OSMesa)."};
  cli.add_option("--frames", frames, "Frames per LOD and path")->capture_default_str();
  cli.add_option("--scene", scene_file, "Intestine scene: shipped name or YAML (size, camera, radius)")->capture_default_str();
  CLI11_PARSE(cli, argc, argv);

  try {
    const Scene scene = load_scene(resolve_scene_path(scene_file));
    const IntestineModel model(scene.intestine.params);
    const int n = model.columns();
    const std::vector<double> rest(model.rest().data(), model.rest().data() + 3 * n);
    TubeParams tp;
    tp.radius = scene.intestine.params.intestine_radius;
    TubeBuilder builder(tp, n);
    TubeMesh mesh = builder.make_mesh(kTubeMaxLod);
    // The CPU path's surface input, sized for the finest LOD (as IntestineView holds it).
    Eigen::MatrixX3f positions(static_cast<Eigen::Index>(mesh.positions.size() / 3), 3);
    Eigen::MatrixX3i tris(static_cast<Eigen::Index>(mesh.indices.size() / 3), 3);
    auto renderer = make_renderer("osmesa", scene.visual.width, scene.visual.height);
    if (!renderer->gpu_skinning()) {
      std::fprintf(stderr, "tube_skinning_bench: %s has no GPU skinning\n", renderer->info().c_str());
      return 1;
    }
    const Eigen::Vector3f pink(0.86f, 0.46f, 0.42f);
    std::vector<double> points(rest);

    std::printf("tube_skinning_bench: %s, %dx%d, %d points, %d frames per LOD and path (wall ms; p50 / p90)\n",
                renderer->info().c_str(), scene.visual.width, scene.visual.height, n, frames);
    std::printf("| LOD | triangles | CPU build | CPU frame p50 | CPU frame p90 | GPU build | GPU frame p50 | GPU frame p90 "
                "| CPU/GPU (p50) | sent per frame CPU / GPU (KiB) |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for (int lod = 0; lod <= kTubeMaxLod; ++lod) {
      Timing timing[2];  // 0: CPU, 1: GPU
      int triangles = 0, vertices = 0, intervals = 0;
      // Alternate the paths frame by frame so that both see the same machine load.
      for (int f = 0; f < 2 * frames + 4; ++f) {
        const bool gpu = f % 2 == 1;
        // A small travelling wave on the body: a new shape every frame.
        const double phase = 0.2 * f;
        for (int i = 0; i < n; ++i) points[3 * i + 2] = rest[3 * i + 2] + 0.004 * std::sin(0.3 * i + phase);
        const auto t0 = Clock::now();
        const bool ok = builder.build(points.data(), n, lod, mesh, gpu ? TubeSkinning::kGpu : TubeSkinning::kCpu);
        if (!ok) {
          std::fprintf(stderr, "tube_skinning_bench: build failed at LOD %d\n", lod);
          return 1;
        }
        if (!gpu) {  // what IntestineView does on the CPU path
          for (int v = 0; v < mesh.vertex_count; ++v) {
            positions.row(v) << mesh.positions[3 * static_cast<std::size_t>(v)],
                mesh.positions[3 * static_cast<std::size_t>(v) + 1], mesh.positions[3 * static_cast<std::size_t>(v) + 2];
          }
          for (int t = 0; t < mesh.index_count / 3; ++t) {
            for (int k = 0; k < 3; ++k) tris(t, k) = static_cast<int>(mesh.indices[static_cast<std::size_t>(3 * t + k)]);
          }
        }
        const double build = ms_since(t0);
        renderer->begin_frame(scene.visual.camera);
        if (gpu) {
          renderer->draw_skinned_tube(builder.primitive(lod), mesh.skin.data(), mesh.intervals, pink);
        } else {
          renderer->draw_surface(positions.topRows(mesh.vertex_count), tris.topRows(mesh.index_count / 3), pink);
        }
        renderer->end_frame();
        const double frame = ms_since(t0);
        triangles = mesh.index_count / 3;
        vertices = mesh.vertex_count;
        intervals = mesh.intervals;
        if (f >= 4) {  // the first frames upload the primitives and grow the buffers
          timing[gpu].build_ms.push_back(build);
          timing[gpu].frame_ms.push_back(frame);
        }
      }
      const double cpu50 = pct(timing[0].frame_ms, 0.5), gpu50 = pct(timing[1].frame_ms, 0.5);
      // Sent per frame: the CPU path's interleaved positions and normals (indices only when they change), the GPU
      // path's two 3 x 4 matrices per interval.
      std::printf("| %d | %d | %.3f | %.2f | %.2f | %.3f | %.2f | %.2f | %.2f | %.1f / %.1f |\n", lod, triangles,
                  pct(timing[0].build_ms, 0.5), cpu50, pct(timing[0].frame_ms, 0.9), pct(timing[1].build_ms, 0.5),
                  gpu50, pct(timing[1].frame_ms, 0.9), gpu50 > 0 ? cpu50 / gpu50 : 0.0,
                  static_cast<double>(vertices) * 6 * sizeof(float) / 1024.0,
                  static_cast<double>(intervals) * 24 * sizeof(float) / 1024.0);
    }
    if (renderer->counts().rejected != 0 || renderer->counts().gl_errors != 0) {
      std::fprintf(stderr, "tube_skinning_bench: %llu draws rejected, %llu frames with GL errors\n",
                   static_cast<unsigned long long>(renderer->counts().rejected),
                   static_cast<unsigned long long>(renderer->counts().gl_errors));
      return 1;
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tube_skinning_bench: %s\n", e.what());
    return 1;
  }
}
