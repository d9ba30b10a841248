// The haptic node: init (scene, input, the organ from the factory, outputs, DDS), run (the fixed-rate loop), shutdown
// (stats). The organ is behind HapticOrgan (organ.h), the DDS entities behind HapticDds (haptic_dds.h): nothing here
// depends on which organ the scene names.
#pragma once
#include <array>
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "async_writer.h"
#include "core/stats.h"
#include "force_stage.h"
#include "organ.h"
#include "scene/scene.h"
#include "tick_trace.h"
#include "tool/trajectory.h"

namespace surgsim {

class HapticDds;
class Publisher;

struct HapticOptions {
  std::string scene = "liver";      // scene YAML path or shipped scene name
  double duration = -1;             // s of simulated time; < 0: the replayed trajectory's length (+0.5 s), else until stopped
  double rate_hz = 0;               // > 0 overrides the scene's haptic rate
  std::string input = "replay";     // "replay" (trajectory file) | "device" (live ToolCommand topic)
  std::string replay;               // trajectory to replay; empty = the scene's default trajectory
  double input_timeout = 0.1;       // s without a ToolCommand before live input counts as lost
  std::string record;               // write the input used as a trajectory file
  double speed = 1.0;               // replay speed; <= 0 means "max" (no pacing, tick-exact)
  std::string log;                  // per-tick CSV
  std::string tick_trace;           // per-tick timing CSV, written after the loop (what made a tick late)
  std::string stats;                // JSON summary on exit
  std::string cache_dir;            // generated meshes and tensors
  int domain = -1;                  // DDS domain; < 0 = default ($SURGSIM_DOMAIN or 0)
  std::string dds_profiles;         // Fast DDS XML; empty = <config>/dds/profiles.xml
  std::string dds_participant;      // empty: $SURGSIM_DDS_PARTICIPANT, else surgsim_default
  int rt_priority = 80;             // SCHED_FIFO priority; 0 = normal scheduling
  int dds_rt_priority = 20;         // SCHED_FIFO priority of the DDS threads (below the loop); 0 = normal scheduling
  bool lock_memory = true;
  int cpu = -1;                     // pin the loop thread to this CPU, the node's other threads off it (-1: don't)
  int tracker_threads = 1;          // the multirate liver's tracker: numeric threads (OrganBuildOptions)
  int cpu_latency_us = 0;           // CPU wake-up latency asked while the paced loop runs (os/cpu_latency.h); -1: none
  double wait_for_visual = 0;       // s to wait for a visual node to match before starting (0 = don't wait)
  bool quiet = false;
};

class HapticApp {
 public:
  explicit HapticApp(const HapticOptions& options);  // init: throws surgsim::core::Error / std::runtime_error
  ~HapticApp();
  HapticApp(const HapticApp&) = delete;
  HapticApp& operator=(const HapticApp&) = delete;

  /// Runs the loop until the duration is reached or stop() is called. Returns 0 on a clean run.
  int run();
  /// Safe from a signal handler: sets an atomic flag.
  void stop() { stop_requested_.store(true, std::memory_order_relaxed); }
  /// Writes the stats JSON (when asked) and prints the summary line.
  void shutdown();

  /// One loop iteration (tick k): input, contacts, force, hand-off to the publisher thread, log. No allocation, no
  /// DDS call. Public for tests.
  void tick(std::uint64_t k);
  std::uint64_t total_ticks() const { return total_ticks_; }
  /// Drains the publisher (every tick handed over is written, then a final zero force) and stops its thread.
  /// run() calls it at its end; tests that drive tick() themselves call it before reading what was published.
  void finish_publishing();

 private:

  /// Instrument i's pose this tick: its trajectory sample, or its newest device command (held when lost). False when
  /// its input is lost (live: no command for input_timeout; replay: recorded lost).
  bool input_pose(int i, double t, tool::Pose5& pose);

  /// Per-instrument state and statistics (preallocated; index = the scene's tools).
  struct Instrument {
    int track = 0;                          // replay: its column group in the trajectory
    tool::Pose5 held_pose;                  // last good pose (held while its input is lost)
    tool::Pose5 last_command;               // newest device command, its arrival (monotonic ns), commands so far
    std::uint64_t last_command_ns = 0;
    std::uint64_t commands_received = 0;
    ForceStage force_stage;                 // contact damper + passivity observer/controller on its force
    int contacts_max = 0;
    double force_max_n = 0;
    std::uint64_t input_lost_ticks = 0;
    std::uint64_t saturated_ticks = 0;
    std::uint64_t contact_ticks = 0;
    std::uint64_t over_capacity_events = 0;
    std::uint64_t nonfinite_rejected = 0;
  };

  HapticOptions options_;
  scene::Scene scene_;
  tool::MultiTrajectory trajectory_;
  tool::TrajectoryRecorder recorder_;
  std::FILE* log_ = nullptr;
  std::unique_ptr<AsyncLineWriter> log_writer_;     // --log lines, written off the loop thread
  std::unique_ptr<AsyncLineWriter> record_writer_;  // --record lines, written off the loop thread
  std::unique_ptr<HapticOrgan> organ_;     // the scene's organ (make_haptic_organ)
  std::unique_ptr<HapticDds> dds_;
  std::unique_ptr<Publisher> publisher_;  // the thread that writes what tick() hands over (publisher.h)
  std::uint64_t tick_due_ns_ = 0;         // monotonic due time of the running tick, period (0: unpaced)
  std::uint64_t period_ns_ = 0;
  int instrument_count_ = 1;
  std::array<Instrument, tool::kMaxInstruments> instruments_{};
  bool live_ = false;
  std::atomic<bool> stop_requested_{false};

  double rate_hz_ = 300;
  double dt_ = 1.0 / 300;
  std::uint64_t total_ticks_ = 0;    // 0 = unbounded
  std::uint64_t ticks_done_ = 0;
  std::uint64_t scene_hash_ = 0;
  std::string realtime_note_;
  std::string dds_threads_note_;   // how the DDS threads (and the publisher thread) are scheduled (stats "dds_threads")

  // Tick statistics (preallocated).
  core::SampleRecorder tick_us_;
  core::SampleRecorder tick_cpu_us_;  // the loop thread's CPU time per tick (tick_us_ is wall time)
  /// --tick-trace: one row per tick, kept in memory during the loop (preallocated) and written after it.
  std::vector<TickTrace> tick_trace_;
  std::FILE* tick_trace_file_ = nullptr;
  void write_tick_trace();
  core::SampleRecorder wake_late_us_;
  std::int64_t deadline_misses_ = 0;
  int contacts_max_ = 0;
  double force_max_n_ = 0;
  std::uint64_t input_lost_ticks_ = 0;      // ticks with at least one instrument's input lost
  std::uint64_t contact_ticks_ = 0;
  std::uint64_t record_writer_stats_ = 0;   // lines dropped (ring full) or failed to write
  std::uint64_t log_writer_stats_ = 0;
  double wall_seconds_ = 0;
  std::string cpu_latency_note_;          // the CPU latency request while the loop ran
  std::string placement_note_;            // where the threads other than the loop went (--cpu)
  int other_threads_on_loop_cpu_ = -1;    // threads besides the loop that may run on its CPU (-1: not pinned)
  long loop_involuntary_switches_ = 0;    // the loop thread's context switches and page faults during the loop
  long loop_voluntary_switches_ = 0;
  long loop_page_faults_ = 0;
  std::uint64_t loop_start_ns_ = 0;  // monotonic, when tick 0 was due (stats: lets tests line up other processes)
};

}  // namespace surgsim
