// intestine_bench: the intestine scene's core at the haptic step (docs/DESIGN.md, section 'Budgets': 400 masses +
// collisions >= 1 kHz).
// Prints tables; run by hand (not a ctest): build/bench/intestine_bench [--quick].
//   1. step time p50 / p99 (model + detection + response) at dt = 1 ms over the scripted run;
//   2. integrator stability against spring stiffness at dt = 1 ms (implicit vs explicit);
//   3. detection recall against the brute-force reference and time per step against the random pairs n
//      (the paper's fig. 14 as numbers);
//   3b. the three detectors side by side on the same positions of the same run: the stochastic one (the loop's), the
//      brute-force reference and the exact broad phase, thread CPU time p50 / p99 and recall against the reference,
//      intestine-intestine and intestine-mesentery contacts apart;
//   4. tube build time and size per LOD; mesentery strip;
//   5. the frame-rate controller (paper eq. 15) under a synthetic load step: LOD band, mean rate and settling time
//      (frames and seconds) per target, the paper's law as printed against the default (log2 error).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "intestine/broad_phase.h"
#include "intestine/frame_rate_controller.h"
#include "intestine/intestine_model.h"
#include "intestine_run.h"
#include "support/intestine_test_util.h"
#include "intestine/tube_geometry.h"

using namespace surgsim::intestine;

namespace {

using namespace surgsim::intestine;
using surgsim::bench::percentile;
using surgsim::bench::thread_cpu_us;
using surgsim::bench::us_since;
using Clock = surgsim::bench::WallClock;
using surgsim::intestine::bench::RunResult;
using surgsim::intestine::bench::scripted_run;

void step_table(int steps) {
  std::printf("\n1. Step time at dt = 1 ms, default model (4 x 100 masses, implicit Euler), scripted run of %.1f s, once "
              "per detector (intestine.detector)\n", steps * 1e-3);
  auto row = [](const char* name, const std::vector<double>& v) {
    std::printf("%-34s %9.1f %9.1f %9.1f\n", name, percentile(v, 0.5), percentile(v, 0.99), percentile(v, 1.0));
  };
  for (const CollisionDetector detector : {CollisionDetector::kStochastic, CollisionDetector::kBroadPhase}) {
    IntestineParams params;
    params.detector = detector;
    std::printf("%-34s %9s %9s %9s   detector: %s%s\n", "phase", "p50 us", "p99 us", "max us", to_string(detector),
                detector == CollisionDetector::kStochastic ? " (n = 10)" : " (exact)");
    const RunResult r = scripted_run(params, steps, 0);
    row("mass-spring (probe, implicit)", r.dynamics);
    row("detection", r.detection);
    row("response", r.response);
    row("step (model + detection + resp.)", r.total);
    row("step, thread CPU time", r.cpu);
    std::printf("contacts per step: mean %.1f, max %d; faults %d; capable of %.0f Hz at the CPU-time p99 (%.0f Hz at "
                "the wall-clock p99, which includes preemption on this shared machine)\n", r.contacts_mean,
                r.contacts_max, r.faults, 1e6 / percentile(r.cpu, 0.99), 1e6 / percentile(r.total, 0.99));
    // The same run again, each phase in thread CPU time (detection's budget, and that of everything else).
    const IntestineModel model(params);
    IntestineState state(model, 1);
    StepReport report;
    std::vector<double> dynamics, detection, response;
    for (int s = 0; s < steps; ++s) {
      const double c0 = thread_cpu_us();
      step_dynamics(model, state, test::scripted_probe(s * 1e-3), 1e-3, report);
      const double c1 = thread_cpu_us();
      step_detection(model, state, report);
      const double c2 = thread_cpu_us();
      step_response(model, state, report);
      response.push_back(thread_cpu_us() - c2);
      detection.push_back(c2 - c1);
      dynamics.push_back(c1 - c0);
    }
    row("mass-spring, thread CPU time", dynamics);
    row("detection, thread CPU time", detection);
    row("response, thread CPU time", response);
  }
}

void stability_table() {
  std::printf("\n2. Integrator stability at dt = 1 ms: 1 s from the rest shape perturbed by 2 mm, all springs at k\n");
  std::printf("%-10s %-30s %-30s\n", "k (N/m)", "implicit Euler: max dE / E0", "symplectic Euler: max dE / E0");
  for (double k : {1e2, 1e3, 1e4, 1e5, 1e6}) {
    std::string cells[2];
    for (int i = 0; i < 2; ++i) {
      IntestineParams p;
      p.structural_stiffness = p.shear_stiffness = p.bending_stiffness = k;
      const IntestineModel model(p);
      const MassSpring& sys = model.mass_spring();
      std::mt19937 rng(3);
      std::uniform_real_distribution<double> u(-0.002, 0.002);
      Eigen::Matrix3Xd x = sys.rest(), v = Eigen::Matrix3Xd::Zero(3, sys.node_count());
      for (int n = 0; n < sys.node_count(); ++n) {
        if (!sys.fixed(n)) x.col(n) += Eigen::Vector3d(u(rng), u(rng), u(rng));
      }
      MassSpringWorkspace work(sys);
      const double e0 = sys.kinetic_energy(v) + sys.potential_energy(x);
      const double scale = std::abs(e0 - sys.potential_energy(sys.rest()));
      double worst = 0;
      int blew = -1;
      for (int s = 0; s < 1000 && blew < 0; ++s) {
        const IntegrateStatus st =
            integrate(sys, i == 0 ? Integrator::kImplicitEuler : Integrator::kSymplecticEuler, nullptr, 0, 1e-3, x, v,
                      work);
        const double e = sys.kinetic_energy(v) + sys.potential_energy(x);
        if (st != IntegrateStatus::kOk || !std::isfinite(e) || e - e0 > 1e6 * scale) blew = s;
        worst = std::max(worst, (e - e0) / scale);
      }
      char buf[64];
      if (blew >= 0) {
        std::snprintf(buf, sizeof buf, "blew up at step %d", blew);
      } else {
        std::snprintf(buf, sizeof buf, "%+.3g", worst);
      }
      cells[i] = buf;
    }
    std::printf("%-10.0e %-30s %-30s\n", k, cells[0].c_str(), cells[1].c_str());
  }
}

void recall_table(int steps) {
  std::printf("\n3. Detection against the brute-force reference over the scripted run (%.1f s, compared every 10 steps "
              "on the same positions)\n", steps * 1e-3);
  std::printf("%-22s %8s %8s %8s %10s %10s %9s %9s %9s %9s\n", "random pairs n", "pairs", "zones", "depth",
              "missed mm", "left mm", "det p50", "det p99", "step p50", "cpu p99");
  auto row = [&](const char* label, const IntestineParams& p) {
    const RunResult r = scripted_run(p, steps, 10);
    std::printf("%-22s %8.3f %8.3f %8.3f %10.2f %10.2f %9.1f %9.1f %9.1f %9.1f\n", label, r.recall.pair_recall(),
                r.recall.region_recall(), r.recall.depth_recall(), 1e3 * r.recall.max_missed, 1e3 * r.residual,
                percentile(r.detection, 0.5), percentile(r.detection, 0.99), percentile(r.total, 0.5),
                percentile(r.cpu, 0.99));
  };
  for (int n : {0, 5, 10, 20, 50, 100}) {
    IntestineParams p;
    p.detector = CollisionDetector::kStochastic;
    p.detection.random_pairs = p.detection.random_mesentery_pairs = n;
    row(std::to_string(n).c_str(), p);
  }
  IntestineParams paper;
  paper.detector = CollisionDetector::kStochastic;
  paper.detection.zone_budget = 0;
  row("10, minima only", paper);
  std::printf("pairs: reference contacts reported; zones: contact zones with at least one reported; depth: weighted by "
              "penetration;\nmissed: deepest reference contact not reported; left: deepest penetration after the "
              "response; times in us (det: wall clock; cpu: the step's thread CPU time).\n");
}

// The contacts of `in` of one kind, appended to `out`.
void of_kind(const ContactList& in, ContactKind kind, ContactList& out) {
  for (const auto& c : in) {
    if (c.kind == kind) out.push(c);
  }
}

void detector_table(int steps) {
  std::printf("\n3b. Detectors side by side at n = 10 on the same positions (the scripted run, %.1f s, every step; recall "
              "every 10 steps), thread CPU time\n", steps * 1e-3);
  IntestineParams params;
  params.detector = CollisionDetector::kStochastic;  // the run's own contacts (and response) are the stochastic ones
  const IntestineModel model(params);
  IntestineState state(model, 1);
  BroadPhaseDetector broad(model.topology());
  StepReport report;
  ContactList truth(100000), exact(100000), kind_found(100000), kind_truth(100000);
  std::vector<double> t[3];
  RecallStats recall[2][2];  // [stochastic, broad phase][intestine-intestine, intestine-mesentery]
  long contacts[2] = {0, 0};
  double tests[3] = {0, 0, 0};  // per step: stochastic distance tests, -, broad phase box overlaps
  for (int s = 0; s < steps; ++s) {
    step_dynamics(model, state, test::scripted_probe(s * 1e-3), 1e-3, report);
    double c0 = thread_cpu_us();
    step_detection(model, state, report);
    t[0].push_back(thread_cpu_us() - c0);
    tests[0] += static_cast<double>(report.detection.distance_tests) / steps;
    truth.clear();
    c0 = thread_cpu_us();
    detect_brute_force(model.topology(), state.x, truth);
    t[1].push_back(thread_cpu_us() - c0);
    exact.clear();
    c0 = thread_cpu_us();
    tests[2] += static_cast<double>(broad.detect(state.x, exact).overlaps) / steps;
    t[2].push_back(thread_cpu_us() - c0);
    if (s % 10 == 0) {
      for (int k = 0; k < 2; ++k) {
        const ContactKind kind = k == 0 ? ContactKind::kSegmentSegment : ContactKind::kSegmentTriangle;
        kind_truth.clear();
        of_kind(truth, kind, kind_truth);
        contacts[k] += kind_truth.size();
        for (int d = 0; d < 2; ++d) {
          kind_found.clear();
          of_kind(d == 0 ? state.contacts() : exact, kind, kind_found);
          recall[d][k] += compare_with_reference(model.topology(), kind_found, kind_truth);
        }
      }
    }
    step_response(model, state, report);
  }
  std::printf("%-26s %9s %9s %9s | %-27s | %-27s | %s\n", "detector", "p50 us", "p99 us", "max us",
              "intestine-intestine recall", "intestine-mesentery recall", "tests");
  std::printf("%-26s %9s %9s %9s | %8s %8s %9s | %8s %8s %9s | %s\n", "", "", "", "", "pairs", "depth", "missed mm",
              "pairs", "depth", "missed mm", "per step");
  const char* names[3] = {"stochastic (n = 10)", "brute force (reference)", "broad phase (box hierarchy)"};
  for (int d = 0; d < 3; ++d) {
    std::printf("%-26s %9.1f %9.1f %9.1f |", names[d], percentile(t[d], 0.5), percentile(t[d], 0.99),
                percentile(t[d], 1.0));
    for (int k = 0; k < 2; ++k) {
      if (d == 1) {
        std::printf(" %8.3f %8.3f %9.2f |", 1.0, 1.0, 0.0);
      } else {
        const RecallStats& r = recall[d == 0 ? 0 : 1][k];
        std::printf(" %8.3f %8.3f %9.2f |", r.pair_recall(), r.depth_recall(), 1e3 * r.max_missed);
      }
    }
    if (d == 1) {
      std::printf(" all\n");
    } else {
      std::printf(" %.0f\n", tests[d]);
    }
  }
  std::printf("reference contacts compared: %ld intestine-intestine, %ld intestine-mesentery (segment-triangle: point-, "
              "edge-triangle and crossing); pairs: share of reference contacts reported, depth: weighted by "
              "penetration;\ntests per step: the stochastic detector's element distance evaluations (exact tests and bounding-sphere "
              "rejections), the broad phase's element pairs whose grown boxes overlap (each gets the exact test)\n",
              contacts[0], contacts[1]);
}

void tube_table() {
  std::printf("\n4. Tube build (spline, curvature samples, ring guard, RMF, CPU skinning) on the intestine after 1 s "
              "of the scripted run\n");
  const IntestineModel model(IntestineParams{});
  IntestineState state(model, 1);
  StepReport report;
  for (int s = 0; s < 1000; ++s) step(model, state, test::scripted_probe(s * 1e-3), 1e-3, report);
  TubeBuilder builder(TubeParams{}, model.columns());
  TubeMesh mesh = builder.make_mesh(kTubeMaxLod);
  std::printf("%-4s %-14s %9s %9s %9s %11s %11s\n", "LOD", "sides x rings", "intervals", "vertices", "triangles",
              "build p50us", "cpu p99us");
  for (int lod = 0; lod <= kTubeMaxLod; ++lod) {
    std::vector<double> t, c;
    for (int i = 0; i < 200; ++i) {
      const double c0 = thread_cpu_us();
      const auto t0 = Clock::now();
      builder.build(state.positions(), model.columns(), lod, mesh);
      t.push_back(us_since(t0));
      c.push_back(thread_cpu_us() - c0);
    }
    const TubeLod l = tube_lod(lod);
    std::printf("%-4d %2d x %-9d %9d %9d %9d %11.1f %11.1f\n", lod, l.sides, l.rings, mesh.intervals,
                mesh.vertex_count, mesh.index_count / 3, percentile(t, 0.5), percentile(c, 0.99));
  }
  const TubeStats& st = builder.stats();
  std::printf("samples %d (flagged segments %d, extra %d, removed %d), rings turned %d, narrowed %d (narrowest %.1f "
              "mm)\n", st.samples, st.flagged_segments, st.extra_samples, st.removed_samples, st.tilted_rings,
              st.narrowed_rings, 1e3 * st.min_radius);
  MesenteryMesh strip = make_mesentery_mesh(model.rows(), model.columns());
  std::vector<double> t;
  for (int i = 0; i < 200; ++i) {
    const auto t0 = Clock::now();
    mesentery_strip(state.positions(), strip);
    t.push_back(us_since(t0));
  }
  std::printf("mesentery strip: %d vertices, %d strip indices, %.1f us\n", strip.vertex_count, strip.index_count,
              percentile(t, 0.5));
}

// One run of the controller on the synthetic load: 600 frames at load x s0, then 600 at x s1. Returns the frames from
// the step until the LOD stays within the band it uses over the last 300 frames, and that band, the mean rate there.
struct ControllerStep {
  int lo = 0, hi = 0, settle_frames = 0;
  double mean_hz = 0;
};

ControllerStep controller_step(const FrameRateParams& p, double s0, double s1) {
  auto fps = [](int lod, double scale) { return 1.0 / (scale * (0.004 + 2.5e-7 * 800.0 * std::pow(2.0, lod))); };
  FrameRateController ctl(p);
  for (int k = 0; k < 600; ++k) ctl.update(fps(ctl.lod(), s0));
  std::vector<int> lods;
  ControllerStep r;
  for (int k = 0; k < 600; ++k) {
    lods.push_back(ctl.lod());
    const double f = fps(ctl.lod(), s1);
    if (k >= 300) r.mean_hz += f / 300;
    ctl.update(f);
  }
  r.lo = *std::min_element(lods.begin() + 300, lods.end());
  r.hi = *std::max_element(lods.begin() + 300, lods.end());
  for (int k = 0; k < 600; ++k) {
    if (lods[static_cast<std::size_t>(k)] < r.lo || lods[static_cast<std::size_t>(k)] > r.hi) r.settle_frames = k + 1;
  }
  return r;
}

void controller_table() {
  std::printf("\n5. Frame-rate controller (eq. 15) under a synthetic load: frame time = load x (4 ms + 0.25 us x "
              "triangles),\n   800 2^LOD triangles; 600 frames at one load, then a step to the other; settling = frames "
              "(and seconds\n   at the target rate) from the step until the LOD stays in the band it uses over the last "
              "300 frames.\n   paper: e = f0 - f (Hz), alpha = 1e-4, beta = 5 (as printed); log2: e = log2(f0 / f), "
              "alpha = 0.1, beta = 5 (the default)\n");
  auto fps = [](int lod) { return 1.0 / (0.004 + 2.5e-7 * 800.0 * std::pow(2.0, lod)); };
  std::printf("LOD rates at load x1:");
  for (int l = 0; l <= kTubeMaxLod; ++l) std::printf(" %d: %.0f Hz", l, fps(l));
  std::printf("\n%-7s %-10s %-6s %-8s %-9s %-14s %-10s\n", "law", "target Hz", "step", "LOD band", "mean Hz",
              "settle frames", "settle s");
  double worst_s = 0;
  for (const char* law : {"paper", "log2"}) {
    for (double target : {30.0, 60.0, 100.0, 150.0, 200.0}) {
      for (const auto& [s0, s1] : {std::pair{1.0, 3.0}, std::pair{3.0, 1.0}}) {
        FrameRateParams p = FrameRateParams::paper(target);
        if (law[0] == 'l') {
          p = FrameRateParams{};
          p.target_hz = target;
        }
        const ControllerStep r = controller_step(p, s0, s1);
        char step[16], band[16];
        std::snprintf(step, sizeof step, "x%.0f>x%.0f", s0, s1);
        std::snprintf(band, sizeof band, r.lo == r.hi ? "%d" : "%d-%d", r.lo, r.hi);
        const double seconds = r.settle_frames / target;
        if (law[0] == 'l') worst_s = std::max(worst_s, seconds);
        std::printf("%-7s %-10.0f %-6s %-8s %-9.1f %-14d %-10.3f\n", law, target, step, band, r.mean_hz,
                    r.settle_frames, seconds);
      }
    }
  }
  std::printf(
      "controller_settle_worst_s %.3f (log2 law, every target and step; budget: the frame-rate controller "
      "settles within 1 s)\n",
      worst_s);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"intestine_bench: step time, integrator stability, detection recall, tube LODs, frame-rate control"};
  bool quick = false;
  std::vector<std::string> only;
  app.add_flag("--quick", quick, "shorter runs (1.7 s scripted run instead of 3.4 s)");
  app.add_option("--only", only, "run only these tables (1 2 3 3b 4 5; default: all), e.g. for profiling")
      ->check(CLI::IsMember({"1", "2", "3", "3b", "4", "5"}));
  CLI11_PARSE(app, argc, argv);
  const int steps = quick ? 1700 : 3400;
  auto run = [&](const char* table) { return only.empty() || std::find(only.begin(), only.end(), table) != only.end(); };
  std::printf("intestine_bench (times are wall-clock on this machine, single thread)\n");
  if (run("1")) step_table(steps);
  if (run("2")) stability_table();
  if (run("3")) recall_table(steps);
  if (run("3b")) detector_table(steps);
  if (run("4")) tube_table();
  if (run("5")) controller_table();
  return 0;
}
