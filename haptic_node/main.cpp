// haptic_node: tool input -> collision -> contacts -> force at the haptic rate; publishes ContactFrames.
#include <CLI/CLI.hpp>
#include <csignal>
#include <iostream>
#include <string>

#include "haptic_app.h"

namespace {
surgsim::HapticApp* g_app = nullptr;
void on_signal(int) {
  if (g_app != nullptr) g_app->stop();
}
}  // namespace

int main(int argc, char** argv) {
  surgsim::HapticOptions o;
  std::string speed = "1";
  CLI::App cli{"surgsim haptic node: replays or receives tool motion, detects contacts and computes forces at the "
               "haptic rate, publishes contact frames over DDS."};
  cli.add_option("--scene", o.scene, "Scene YAML file or shipped scene name")->capture_default_str();
  cli.add_option("--duration", o.duration, "Stop after S seconds of simulated time (default: trajectory length + 0.5 s)");
  cli.add_option("--rate", o.rate_hz, "Haptic rate override, Hz");
  cli.add_option("--input", o.input, "Tool input: replay (a trajectory file) or device (live ToolCommand topic)")
      ->capture_default_str();
  cli.add_option("--input-timeout", o.input_timeout, "Seconds without a device command before the input counts as lost "
                 "(force zeroed, tool held)")->capture_default_str();
  cli.add_option("--replay", o.replay, "Tool trajectory to replay (default: the scene's)");
  cli.add_option("--record", o.record, "Write the tool input used to this trajectory file");
  cli.add_option("--speed", speed, "Replay speed factor, or 'max' (as fast as possible, tick-exact)")->capture_default_str();
  cli.add_option("--log", o.log, "Per-tick CSV: tick,t,fx,fy,fz,contacts");
  cli.add_option("--tick-trace", o.tick_trace,
                 "Per-tick timing CSV written after the loop: tick,due_us,wake_late_us,"
                 "tick_us,tick_cpu_us,misses, then the contact step's stages track_points_us,build_patches_us,"
                 "solve_active_set_us,friction_us,distribute_forces_us (0 for the intestine): what made a tick late");
  cli.add_option("--stats", o.stats, "Write a JSON summary here on exit");
  cli.add_option("--cache", o.cache_dir, "Cache folder for generated meshes and tensors (default $SURGSIM_CACHE_DIR or ~/.cache/surgsim)");
  cli.add_option("--domain", o.domain, "DDS domain id (default $SURGSIM_DOMAIN or 0)");
  cli.add_option("--dds-profiles", o.dds_profiles, "Fast DDS XML profiles file (default config/dds/profiles.xml)");
  cli.add_option("--dds-participant", o.dds_participant, "Participant profile: surgsim_default, surgsim_shm, surgsim_udp, "
                 "surgsim_udp_peers, surgsim_ds_client (default $SURGSIM_DDS_PARTICIPANT or surgsim_default)");
  cli.add_option("--rt-priority", o.rt_priority, "SCHED_FIFO priority for the loop (0 = normal scheduling)")->capture_default_str();
  cli.add_option("--dds-rt-priority", o.dds_rt_priority,
                 "SCHED_FIFO priority for the DDS receive threads, below the loop's (0 = normal scheduling; not used "
                 "with --speed max)")
      ->check(CLI::Range(0, 99))
      ->capture_default_str();
  cli.add_flag("!--no-mlock", o.lock_memory, "Do not lock memory");
  cli.add_option("--cpu", o.cpu, "Pin the loop thread to this CPU and keep the node's other threads (DDS, publisher, "
                 "log writers, the multirate liver's tracker) off it (default -1: not pinned; scripts/run_local.sh gives "
                 "$SURGSIM_HAPTIC_CPU)");
  cli.add_option("--cpu-latency-us", o.cpu_latency_us,
                 "While the paced loop runs, ask the kernel to keep every CPU's wake-up latency at most this (PM QoS, "
                 "/dev/cpu_dma_latency; 0: idle CPUs poll instead of halting, so a virtual machine's CPU is awake when "
                 "the loop's timer fires); -1: ask nothing")
      ->capture_default_str();
  cli.add_option("--tracker-threads", o.tracker_threads,
                 "Threads of the multirate liver's tracker (liver.deformation multirate; CHOLMOD's OpenMP and "
                 "OpenBLAS). 1 beside the visual node on 2 CPUs (a second thread waits for the renderer); more where "
                 "CPUs are spare")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  cli.add_option("--wait-for-visual", o.wait_for_visual, "Wait up to S seconds for a visual node before starting");
  cli.add_flag("--quiet", o.quiet, "Print nothing but errors");
  CLI11_PARSE(cli, argc, argv);

  if (speed == "max") {
    o.speed = 0;
  } else {
    try {
      std::size_t used = 0;
      o.speed = std::stod(speed, &used);
      if (used != speed.size() || !(o.speed > 0)) throw std::invalid_argument(speed);
    } catch (const std::exception&) {
      std::cerr << "haptic_node: --speed '" << speed << "' is not a positive number or 'max'\n";
      return 2;
    }
  }

  try {
    surgsim::HapticApp app(o);
    g_app = &app;
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    const int rc = app.run();
    app.shutdown();
    g_app = nullptr;
    return rc;
  } catch (const std::exception& e) {
    std::cerr << "haptic_node: " << e.what() << "\n";
    return 1;
  }
}
