// visual_node: receives contact frames, deforms the visible mesh and renders it off-screen (OSMesa).
#include <CLI/CLI.hpp>
#include <csignal>
#include <iostream>

#include "visual_app.h"

namespace {
surgsim::VisualApp* g_app = nullptr;
void on_signal(int) {
  if (g_app != nullptr) g_app->stop();
}
}  // namespace

int main(int argc, char** argv) {
  surgsim::VisualOptions o;
  CLI::App cli{"surgsim visual node: receives contact frames over DDS, deforms the visible mesh and renders it "
               "off-screen with OSMesa into PNG frames."};
  cli.add_option("--scene", o.scene, "Scene YAML file or shipped scene name")->capture_default_str();
  cli.add_option("--duration", o.duration, "Stop after S seconds of wall time (default: until SIGINT/SIGTERM)");
  cli.add_option("--idle-exit", o.idle_exit, "Exit S seconds after contact frames stop arriving (0 = never)");
  cli.add_option("--out", o.out, "Folder for PNG frames and VTK files")->capture_default_str();
  cli.add_flag("--headless", o.headless, "No GL context: deformation only (null renderer)");
  cli.add_option("--stats", o.stats, "Write a JSON summary here on exit");
  cli.add_option("--rate", o.rate_hz, "Visual frame rate override, Hz");
  cli.add_option("--png-every", o.png_every, "Write every n-th frame as PNG (0 = none; default from the scene)");
  cli.add_option("--tube-skinning", o.tube_skinning,
                 "Intestine tube: 'gpu' skins the cylinder primitive in a vertex shader (only the per-interval "
                 "matrices are sent per frame), 'cpu' skins it on the CPU and uploads the vertices")
      ->check(CLI::IsMember({"gpu", "cpu"}))
      ->capture_default_str();
  cli.add_option("--dds-rt-priority", o.dds_rt_priority,
                 "SCHED_FIFO priority for the DDS receive threads, so contact frames preempt rendering (0 = normal "
                 "scheduling; the haptic node's loop runs at 80)")
      ->check(CLI::Range(0, 99))
      ->capture_default_str();
  cli.add_flag("--video", o.video, "Also assemble the PNG frames into out/video.mp4 with ffmpeg (when installed)");
  cli.add_option("--cache", o.cache_dir, "Cache folder for generated meshes and tensors");
  cli.add_option("--domain", o.domain, "DDS domain id (default $SURGSIM_DOMAIN or 0)");
  cli.add_option("--dds-profiles", o.dds_profiles, "Fast DDS XML profiles file (default config/dds/profiles.xml)");
  cli.add_option("--dds-participant", o.dds_participant, "Participant profile: surgsim_default, surgsim_shm, surgsim_udp, "
                 "surgsim_udp_peers, surgsim_ds_client (default $SURGSIM_DDS_PARTICIPANT or surgsim_default)");
  cli.add_option("--stream-fps", o.stream_fps,
                 "Publish the rendered frames JPEG-compressed on surgsim/frame at this rate for surgsim-web, Hz "
                 "(0 = off; default: the scene's visual.stream_fps, itself 0)")
      ->check(CLI::Range(0.0, 120.0));
  cli.add_option("--stream-quality", o.stream_quality,
                 "JPEG quality of the streamed frames, 1..100 (default: the scene's visual.stream_quality, 75)")
      ->check(CLI::Range(1, 100));
  cli.add_flag("--quiet", o.quiet, "Print nothing but errors");
  CLI11_PARSE(cli, argc, argv);

  try {
    surgsim::VisualApp app(o);
    g_app = &app;
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    const int rc = app.run();
    app.shutdown();
    g_app = nullptr;
    return rc;
  } catch (const std::exception& e) {
    std::cerr << "visual_node: " << e.what() << "\n";
    return 1;
  }
}
