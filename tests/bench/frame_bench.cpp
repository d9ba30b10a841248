// frame_bench: what the web view's frame stream costs. For each resolution (320x240, 640x480, 1280x720)
// the shipped liver is rendered with OSMesa (the tool moving a little every frame, as while pressing) and each picture
// is JPEG-compressed by the visual node's codec (libturbojpeg) at quality 50, 75 and 90:
//   - the encode time (wall and this thread's CPU, us) and the JPEG size (KiB) per frame, against the frame period;
//   - what the render loop itself pays per streamed frame: reading the picture back (glReadPixels into the
//     preallocated slot) and handing it to the encoder thread (FrameStream acquire + submit), against the 20 ms of a
//     50 Hz frame.
// Usage: frame_bench [--frames N] [--out DIR] (DIR/frame_encode.csv, DIR/frame_render_loop.csv).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <vector>

#include "bench_util.h"
#include "core/clock.h"
#include "core/stats.h"
#include "csv_out.h"
#include "frame_stream.h"
#include "mesher/scene_mesh.h"
#include "organ_view.h"
#include "render/renderer.h"
#include "scene/scene.h"
#include "tool/tool.h"

using namespace surgsim::core;
using namespace surgsim::tool;
using namespace surgsim::scene;
using namespace surgsim::mesher;

int main(int argc, char** argv) {
  using namespace surgsim;
  int frames = 120;
  std::string out;
  CLI::App cli{"frame_bench: JPEG encode time and size of the web view's frames per resolution and quality (the "
               "shipped liver rendered with OSMesa), and the cost of a streamed frame on the render loop"};
  cli.add_option("--frames", frames, "Frames per resolution (>= 20)")->check(CLI::Range(20, 100000))
      ->capture_default_str();
  cli.add_option("--out", out, "Write DIR/frame_encode.csv and DIR/frame_render_loop.csv");
  CLI11_PARSE(cli, argc, argv);
  try {
    bench::make_dirs(out);
    bench::CsvOut encode_csv(out, "frame_encode",
                             "width,height,quality,encode_p50_us,encode_p99_us,encode_max_us,cpu_p50_us,cpu_p99_us,"
                             "kib_p50,kib_max,within_bound");
    bench::CsvOut loop_csv(out, "frame_render_loop",
                           "width,height,render_p50_ms,readback_p50_us,readback_p99_us,handoff_p50_us,handoff_p99_us");
    const Scene scene = load_scene(resolve_scene_path("liver"));
    OrganViewOptions oo;
    oo.cache_dir = default_cache_dir();
    auto organ = make_organ_view(scene, oo);
    const int qualities[] = {50, 75, 90};
    std::printf("frame_bench: shipped liver, %d frames per resolution, libturbojpeg 4:2:0, topic bound %u KiB\n",
                frames, msg::kMaxFrameBytes / 1024);
    std::printf("\nJPEG encode per frame (encoder thread; wall and thread CPU us) and size (KiB)\n");
    std::printf("%10s %4s | %9s %9s %9s | %8s %8s | %7s %7s\n", "size", "q", "wall p50", "wall p99", "max", "cpu p50",
                "cpu p99", "KiB p50", "KiB max");
    std::vector<std::tuple<int, int, Percentiles, Percentiles, double>> loop_rows;
    for (auto [w, h] : std::vector<std::pair<int, int>>{{320, 240}, {640, 480}, {1280, 720}}) {
      auto renderer = make_renderer("osmesa", w, h);
      organ->attach(*renderer);
      // Preallocated and touched, as the stream's slot is: the read-back below is the copy alone.
      std::vector<Image> images(static_cast<std::size_t>(frames));
      for (Image& im : images) {
        im.resize(w, h);
        std::fill(im.rgb.begin(), im.rgb.end(), std::uint8_t{0});
      }
      SampleRecorder render_ms(static_cast<std::size_t>(frames)), readback_us(static_cast<std::size_t>(frames));
      for (int f = 0; f < frames; ++f) {
        const double insertion = 0.15 + 0.02 * f / frames;  // the tool going down: every picture differs
        const ToolGeometry tool = tool_geometry(scene.tools[0], Pose5{0.05 * f / frames, 0, insertion, 0, 0.5});
        const std::uint64_t t0 = monotonic_ns();
        organ->update(nullptr, false);
        renderer->begin_frame(scene.visual.camera);
        organ->draw(*renderer);
        renderer->draw_tool(tool, static_cast<float>(scene.tools[0].shaft_radius));
        renderer->end_frame();
        const std::uint64_t t1 = monotonic_ns();
        renderer->read_image(images[static_cast<std::size_t>(f)]);
        render_ms.add(static_cast<double>(t1 - t0) * 1e-6);
        readback_us.add(static_cast<double>(monotonic_ns() - t1) * 1e-3);
      }
      JpegCodec codec;
      std::vector<std::uint8_t> jpeg;
      jpeg.reserve(JpegCodec::max_jpeg_bytes(w, h));
      for (int q : qualities) {
        SampleRecorder wall(static_cast<std::size_t>(frames)), cpu(static_cast<std::size_t>(frames)),
            kib(static_cast<std::size_t>(frames));
        for (const Image& im : images) {
          const std::uint64_t t0 = monotonic_ns();
          const double c0 = bench::thread_cpu_us();
          if (!codec.encode(im, q, jpeg)) throw std::runtime_error(std::string("encode failed: ") + codec.error());
          cpu.add(bench::thread_cpu_us() - c0);
          wall.add(static_cast<double>(monotonic_ns() - t0) * 1e-3);
          kib.add(static_cast<double>(jpeg.size()) / 1024.0);
        }
        const Percentiles pw = wall.summary(), pc = cpu.summary(), pk = kib.summary();
        const bool within = pk.max * 1024.0 <= msg::kMaxFrameBytes;
        std::printf("%4dx%-5d %4d | %9.0f %9.0f %9.0f | %8.0f %8.0f | %7.1f %7.1f%s\n", w, h, q, pw.p50, pw.p99,
                    pw.max, pc.p50, pc.p99, pk.p50, pk.max, within ? "" : "  OVER THE BOUND: dropped");
        encode_csv.row("%d,%d,%d,%.1f,%.1f,%.1f,%.1f,%.1f,%.2f,%.2f,%d", w, h, q, pw.p50, pw.p99, pw.max, pc.p50,
                       pc.p99, pk.p50, pk.max, within ? 1 : 0);
      }
      // The render loop's share: hand the read-back picture to the encoder thread (acquire, copy-free read into the
      // slot is the read-back above; here acquire + submit), one frame at a time as the loop does at 50 Hz.
      SampleRecorder handoff(static_cast<std::size_t>(frames));
      {
        FrameStreamOptions so;
        so.width = w;
        so.height = h;
        FrameStream stream(so, [](const msg::Frame&) {});
        for (int f = 0; f < frames; ++f) {
          stream.wait_idle();
          const std::uint64_t t0 = monotonic_ns();
          Image* slot = stream.acquire();
          if (slot == nullptr) continue;
          std::swap(*slot, images[static_cast<std::size_t>(f)]);  // stands in for read_image (measured above)
          stream.submit(FrameStamp{static_cast<std::uint64_t>(f), t0, 0, 0});
          handoff.add(static_cast<double>(monotonic_ns() - t0) * 1e-3);
        }
        stream.wait_idle();
      }
      loop_rows.emplace_back(w, h, readback_us.summary(), handoff.summary(), render_ms.summary().p50);
    }
    std::printf("\nOn the render loop per streamed frame (us): read-back into the slot, hand-off to the encoder "
                "thread; beside the render itself (ms)\n");
    std::printf("%10s | %9s | %9s %9s | %9s %9s\n", "size", "render p50", "read p50", "read p99", "hand p50",
                "hand p99");
    for (const auto& [w, h, rb, ho, render] : loop_rows) {
      std::printf("%4dx%-5d | %8.2fms | %9.0f %9.0f | %9.1f %9.1f\n", w, h, render, rb.p50, rb.p99, ho.p50, ho.p99);
      loop_csv.row("%d,%d,%.3f,%.1f,%.1f,%.2f,%.2f", w, h, render, rb.p50, rb.p99, ho.p50, ho.p99);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "frame_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
