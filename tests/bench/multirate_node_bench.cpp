// multirate_node_bench: how right the force of the haptic node's multirate liver is while the tool moves,
// as the node computes it: the scene's LiverOrgan with its tracker thread running, stepped at 1 kHz in real time
// along the scene's trajectory (a grasp-and-lift of the free lobe for config/liver_multirate.yaml), next to the same
// scene with the linear model stepped on the same poses. Every --sample-ms of a tick in contact the tick's contact
// targets (the solution's nodes and their imposed displacements, which the tracker is handed) and both forces are
// kept; after the run the neo-Hookean Newton solve of those very targets (fem/hyperelastic.h, the reference the
// tracker converges to) gives the reference force. The error is |F - F_ref| / max(|F_ref|, 5 % of the largest
// |F_ref| of the run) (large_deformation_bench's measure), per sample and per phase of the trajectory. It measures the
// multirate model's lag, extrapolation, partial matches and trust-region blend in the node; the contact kinematics
// (the patch model's linear targets) are the same on both sides of the comparison.
//
// Real time: the loop sleeps to absolute 1 ms deadlines on a normal-priority thread (not SCHED_FIFO: a bench), the
// tracker thread competes for the CPUs with whatever else runs; run it under the lock. Figures vary with the load.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <string>
#include <thread>
#include <vector>

#include "bench_util.h"
#include "core/error.h"
#include "csv_out.h"
#include "fem/fem.h"
#include "fem/hyperelastic.h"
#include "liver/liver_setup.h"
#include "mesher/scene_mesh.h"
#include "organs/liver_organ.h"
#include "scene/scene.h"
#include "support/newton_reference.h"
#include "tool/tool.h"
#include "tool/trajectory.h"

using namespace surgsim::core;
using namespace surgsim::tool;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::contact;
using namespace surgsim::liver;
using namespace surgsim::scene;
using namespace surgsim::mesher;

using namespace surgsim;

namespace {

struct Sample {
  double t = 0;  // s
  std::vector<ImposedDisplacement> targets;
  Eigen::Vector3d multirate = Eigen::Vector3d::Zero();  // N, on the tool
  Eigen::Vector3d linear = Eigen::Vector3d::Zero();     // N, on the tool, the linear scene on the same poses
  Eigen::Vector3d reference = Eigen::Vector3d::Zero();  // N, on the tool, Newton on the same targets
  bool converged = false;
  MultirateUse use = MultirateUse::kNoContact;  // not recorded per tick by the organ: the counters' change
};

const char* phase_of(double t, double lift0, double lift1, double release) {
  if (t < lift0) return "grasp";
  if (t < lift1) return "lift";
  if (t < release) return "hold";
  return "release";
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_name = "liver_multirate", trajectory_path, cache, out_dir;
  double sample_ms = 50, lift0 = 1.45, lift1 = 2.95, release = 3.95;
  int tracker_threads = 1;
  CLI::App app{
      "multirate_node_bench: the multirate liver's force in the haptic node against the neo-Hookean Newton "
      "force of the same contact targets, along a trajectory in real time (the tracker thread running), "
      "with the linear model on the same poses; per-sample table, phase summary, --out DIR writes "
      "DIR/multirate_node.csv"};
  app.add_option("--scene", scene_name, "Scene (name or YAML) with liver.deformation multirate")->capture_default_str();
  app.add_option("--trajectory", trajectory_path, "Trajectory (default: the scene's)");
  app.add_option("--cache", cache, "Mesh and tensor cache folder (default: $SURGSIM_CACHE_DIR, else ~/.cache/surgsim)");
  app.add_option("--sample-ms", sample_ms, "A sample every this many ms of ticks in contact")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 10000.0));
  app.add_option("--lift", lift0, "Start of the lift in the trajectory, s (phase table)")->capture_default_str();
  app.add_option("--hold", lift1, "Start of the hold, s")->capture_default_str();
  app.add_option("--release", release, "Start of the release, s")->capture_default_str();
  app.add_option("--tracker-threads", tracker_threads, "The tracker's numeric threads (haptic_node --tracker-threads)")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  app.add_option("--out", out_dir, "Write multirate_node.csv to this folder (created if missing)");
  CLI11_PARSE(app, argc, argv);

  try {
    if (cache.empty()) cache = default_cache_dir();
    const Scene scene = load_scene(resolve_scene_path(scene_name));
    if (scene.model != "liver" || scene.liver.deformation != LiverDeformation::kMultirate)
      throw Error(scene.file + ": liver.deformation is not multirate (this bench measures the multirate liver)");
    if (trajectory_path.empty()) trajectory_path = scene.trajectory;
    if (trajectory_path.empty()) throw Error(scene.file + ": no trajectory in the scene; give --trajectory FILE");
    const MultiTrajectory traj = MultiTrajectory::load(trajectory_path);
    Scene linear_scene = scene;
    linear_scene.liver.deformation = LiverDeformation::kLinear;

    std::fprintf(stderr, "multirate_node_bench: building the organs (%s)\n", scene.file.c_str());
    LiverOrgan organ(scene, cache, &std::cerr, true, tracker_threads);
    LiverOrgan linear(linear_scene, cache, &std::cerr, false);
    MultirateContacts& mr = *organ.multirate();

    // The run: 1 kHz in real time, the tracker thread cycling as in the node.
    const double dt = 1e-3;
    const int ticks = static_cast<int>(std::ceil(traj.duration() / dt)) + 1;
    const int every = std::max(1, static_cast<int>(std::lround(sample_ms * 1e-3 / dt)));
    std::vector<Sample> samples;
    samples.reserve(static_cast<std::size_t>(ticks / every + 1));
    int since = every;
    std::uint64_t nl0 = 0, pa0 = 0, fb0 = 0;
    std::fprintf(stderr, "multirate_node_bench: %d ticks of %s at 1 kHz in real time\n", ticks,
                 trajectory_path.c_str());
    auto next = std::chrono::steady_clock::now();
    for (int k = 0; k < ticks; ++k) {
      const double t = k * dt;
      Pose5 pose;
      ContactTick tm, tl;
      if (!traj.at(0, t, pose)) continue;
      const ToolGeometry g = tool_geometry(scene.tools[0], pose);
      organ.step(&g, pose.jaw, dt, tm);
      linear.step(&g, pose.jaw, dt, tl);
      const ContactSolution& s = organ.liver_contacts().solution();
      if (s.count > 0 && ++since >= every) {
        since = 0;
        Sample smp;
        smp.t = t;
        for (int l = 0; l < s.count; ++l)
          smp.targets.push_back({s.nodes[static_cast<std::size_t>(l)], s.displacement[static_cast<std::size_t>(l)], 7});
        smp.multirate = tm.force;
        smp.linear = tl.force;
        smp.use = mr.ticks_nonlinear() != nl0         ? MultirateUse::kNonlinear
                  : mr.ticks_partial() != pa0         ? MultirateUse::kPartial
                  : mr.ticks_linear_fallback() != fb0 ? MultirateUse::kLinearFallback
                                                      : MultirateUse::kNoContact;
        samples.push_back(std::move(smp));
      }
      nl0 = mr.ticks_nonlinear();
      pa0 = mr.ticks_partial();
      fb0 = mr.ticks_linear_fallback();
      next += std::chrono::microseconds(1000);
      std::this_thread::sleep_until(next);
    }
    const double cycle_p50 = mr.cycle_ms(0.5), cycle_p99 = mr.cycle_ms(0.99);
    const std::uint64_t cycles = mr.tracker_cycles();
    mr.stop();

    // The references: Newton on each sample's targets (tests/support/newton_reference.h, shared with the haptic
    // node's integration test).
    const test::NewtonReference newton(scene, organ.mesh(), cache);
    double largest = 0;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      Sample& smp = samples[i];
      smp.converged = newton.tool_force(smp.targets, smp.reference);
      if (smp.converged) largest = std::max(largest, smp.reference.norm());
      std::fprintf(stderr, "\rmultirate_node_bench: Newton reference %zu / %zu", i + 1, samples.size());
    }
    std::fprintf(stderr, "\n");

    const double floor = 0.05 * largest;
    const auto rel = [&](const Eigen::Vector3d& f, const Eigen::Vector3d& ref) {
      return test::relative_error(f, ref, floor);
    };
    static const char* kUse[] = {"-", "nonlinear", "partial", "linear"};
    std::printf(
        "Multirate liver in the node (%s, %s): %zu samples every %g ms of contact; tracker %llu cycles, "
        "p50 %.1f ms, p99 %.1f ms\n",
        scene.file.c_str(), trajectory_path.c_str(), samples.size(), sample_ms, static_cast<unsigned long long>(cycles),
        cycle_p50, cycle_p99);
    std::printf("%7s %-8s %6s | %9s %9s %9s | %9s %9s | %s\n", "t s", "phase", "nodes", "|F_ref| N", "|F_mr| N",
                "|F_lin| N", "mr err", "lin err", "tick model");
    bench::CsvOut csv;
    if (!out_dir.empty()) {
      bench::make_dirs(out_dir);
      csv =
          bench::CsvOut(out_dir, "multirate_node",
                        "t_s,phase,nodes,f_ref_n,f_multirate_n,f_linear_n,multirate_rel_error,linear_rel_error,model");
    }
    struct Phase {
      const char* name;
      std::vector<double> mr, lin;
    };
    std::vector<Phase> phases = {
        {"grasp", {}, {}}, {"lift", {}, {}}, {"hold", {}, {}}, {"release", {}, {}}, {"all", {}, {}}};
    int unconverged = 0;
    for (const Sample& smp : samples) {
      const char* ph = phase_of(smp.t, lift0, lift1, release);
      if (!smp.converged) {
        ++unconverged;
        std::printf("%7.3f %-8s %6zu | Newton did not converge on these targets: sample left out\n", smp.t, ph,
                    smp.targets.size());
        continue;
      }
      const double em = rel(smp.multirate, smp.reference), el = rel(smp.linear, smp.reference);
      std::printf("%7.3f %-8s %6zu | %9.4f %9.4f %9.4f | %8.2f%% %8.2f%% | %s\n", smp.t, ph, smp.targets.size(),
                  smp.reference.norm(), smp.multirate.norm(), smp.linear.norm(), 100 * em, 100 * el,
                  kUse[static_cast<int>(smp.use)]);
      csv.row("%.4f,%s,%zu,%.6g,%.6g,%.6g,%.6g,%.6g,%s", smp.t, ph, smp.targets.size(), smp.reference.norm(),
              smp.multirate.norm(), smp.linear.norm(), em, el, kUse[static_cast<int>(smp.use)]);
      for (Phase& p : phases)
        if (std::string(p.name) == ph || std::string(p.name) == "all") {
          p.mr.push_back(em);
          p.lin.push_back(el);
        }
    }
    std::printf(
        "\nforce error against Newton on the same targets, %% (p50 / p99 / max); budget: 5 %% (lift to 45 "
        "degrees), 10 %% (to 90)\n");
    std::printf("%-8s %7s | %26s | %26s\n", "phase", "samples", "multirate", "linear");
    for (const Phase& p : phases) {
      if (p.mr.empty()) continue;
      std::printf("%-8s %7zu | %8.2f %8.2f %8.2f | %8.2f %8.2f %8.2f\n", p.name, p.mr.size(),
                  100 * bench::percentile(p.mr, 0.5), 100 * bench::percentile(p.mr, 0.99),
                  100 * bench::percentile(p.mr, 1.0), 100 * bench::percentile(p.lin, 0.5),
                  100 * bench::percentile(p.lin, 0.99), 100 * bench::percentile(p.lin, 1.0));
    }
    if (unconverged > 0) std::printf("%d samples left out: Newton did not converge on their targets\n", unconverged);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "multirate_node_bench: %s\n", e.what());
    return 1;
  }
}
