// intestine_error_bench: the intestine's error against run time. A plain program run by hand
// (build/bench/intestine_error_bench --out DIR); readable tables on stdout, progress on stderr, and with --out one
// CSV per table (csv_out.h) for the report scripts. --smoke is the tiny configuration its ctest runs.
//   1. time step against a fine-step reference: the scripted probe run (tests/support/intestine_test_util.h) at
//      dt = 0.25 .. 33 ms against dt = 0.1 ms, with and without self-collisions: distance of the intestine's masses
//      to the reference every 10 ms (where the step lands on it) and at the end, probe force error, CPU time per
//      step and per simulated second (intestine_timestep.csv; with --series also the error at each compared time,
//      intestine_timestep_series.csv);
//   2. random pairs n against detection recall (the brute-force reference on the same positions every step), time
//      to detect and time per step (intestine_pairs.csv);
//   3. level of detail against geometric error (the flat triangles of each LOD against the skinned surface they
//      approximate, the limit of infinitely many sides and rings), triangles, tube build time and the OSMesa frame
//      time of the intestine scene at 640 x 480 (intestine_lod.csv);
//   4. the frame-rate controller (paper eq. 15) of the visual node's IntestineView on the real renderer at several
//      targets: rate achieved and LOD chosen (intestine_frame_rate.csv).
#include <CLI/CLI.hpp>
#include <Eigen/Cholesky>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <exception>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "bench_util.h"
#include "csv_out.h"
#include "intestine/frame_rate_controller.h"
#include "intestine/intestine_model.h"
#include "intestine_run.h"
#include "support/intestine_test_util.h"
#include "views/intestine_view.h"
#include "render/renderer.h"
#include "scene/scene.h"
#include "intestine/tube_geometry.h"

using namespace surgsim::intestine;

namespace {

using namespace surgsim::intestine;
using surgsim::bench::CsvOut;
using surgsim::bench::percentile;
using surgsim::bench::thread_cpu_us;
using surgsim::bench::us_since;
using surgsim::bench::WallClock;
using surgsim::intestine::bench::RunResult;
using surgsim::intestine::bench::scripted_run;

struct Config {
  std::string out;                 // CSV folder ("" = tables only)
  bool series = false;             // also intestine_timestep_series.csv (one line per compared time and run)
  double duration = 3.4;           // s, scripted run (the probe's script ends at 3.4 s)
  double reference_dt = 1e-4;      // s
  std::vector<double> dts;         // s, compared with the reference
  std::vector<int> pairs;          // random pairs n
  int compare_every = 2;           // steps between brute-force comparisons (pairs table)
  int states = 30;                 // body states for the LOD table (frames cycle through them)
  int lod_frames = 30;             // frames per LOD
  std::vector<double> targets;     // Hz, frame-rate controller
  int controller_frames = 400;     // per target (statistics over the second half)
  int width = 640, height = 480;
  bool render = true;
};

void progress(const char* what) { std::fprintf(stderr, "intestine_error_bench: %s\n", what); }

// ---------------------------------------------------------------------------------------------------------------
// 1. Time step against a fine-step reference.

constexpr double kComparePeriod = 0.01;  // s: positions compared where a run's step ends on a multiple of this

// Index of the comparison time a step ending at t lands on, or -1.
int compare_index(double t) {
  const double k = std::round(t / kComparePeriod);
  return std::abs(t - k * kComparePeriod) < 1e-9 ? static_cast<int>(k) : -1;
}

// What a run leaves at the comparison times: the intestine's points (3 x columns) and the probe force.
struct Trace {
  std::vector<Eigen::Matrix3Xd> x;     // by comparison index (empty where the run never landed)
  std::vector<Eigen::Vector3d> force;  // N
  std::vector<char> have;
  bool finite = true;
  double max_radius = 0;  // m, farthest intestine point from the vessel's origin
};

struct TimestepRow {
  double dt = 0;
  bool collisions = false;
  RunResult run;
  Trace trace;
  double pos_rms = 0, pos_max = 0, end_rms = 0, end_max = 0;  // m
  double settle_rms = 0;                                      // m, over the times before the probe moves
  double force_rms = 0, force_ref_rms = 0;                    // N
  int compared = 0;
  bool stable = false;
};

// First comparison time at which the scripted probe is active (s): before it the folds only settle under gravity.
double probe_start() {
  int k = 0;
  while (!test::scripted_probe(k * kComparePeriod).active && k < 100000) ++k;
  return k * kComparePeriod;
}

TimestepRow run_timestep(double dt, bool collisions, double duration) {
  IntestineParams p;
  p.self_collisions = collisions;
  const int steps = static_cast<int>(std::lround(duration / dt));
  const int slots = compare_index(steps * dt) + 1;
  TimestepRow row;
  row.dt = dt;
  row.collisions = collisions;
  Trace& tr = row.trace;
  tr.x.resize(static_cast<std::size_t>(std::max(slots, 1)));
  tr.force.assign(tr.x.size(), Eigen::Vector3d::Zero());
  tr.have.assign(tr.x.size(), 0);
  const int cols = p.columns;
  row.run = scripted_run(p, steps, 0, dt, [&](int s, const IntestineState& state, const StepReport& report) {
    const int k = compare_index((s + 1) * dt);
    if (k < 0 || k >= slots) return;
    tr.x[static_cast<std::size_t>(k)] = state.x.leftCols(cols);
    tr.force[static_cast<std::size_t>(k)] = report.probe_force;
    tr.have[static_cast<std::size_t>(k)] = 1;
    if (!state.x.allFinite()) tr.finite = false;
    tr.max_radius = std::max(tr.max_radius, state.x.leftCols(cols).colwise().norm().maxCoeff());
  });
  // Stable: no step refused, everything finite, and the intestine still near its vessel (the rest shape lies 0.15 m
  // from it; 1 m means the run blew up).
  row.stable = row.run.faults == 0 && tr.finite && tr.max_radius < 1.0;
  return row;
}

// Errors of `row` against the reference at the times both landed on; one line per time into `series`.
void compare_with(TimestepRow& row, const TimestepRow& ref, CsvOut& series) {
  const double settle_end = probe_start();
  double sq = 0, fsq = 0, frsq = 0, settle_sq = 0;
  long n = 0, settle_n = 0;
  int last = -1;
  for (std::size_t k = 1; k < row.trace.x.size() && k < ref.trace.x.size(); ++k) {
    if (!row.trace.have[k] || !ref.trace.have[k]) continue;
    const Eigen::VectorXd d = (row.trace.x[k] - ref.trace.x[k]).colwise().norm();
    const double t = static_cast<double>(k) * kComparePeriod;
    const double f = (row.trace.force[k] - ref.trace.force[k]).norm();
    sq += d.squaredNorm();
    n += d.size();
    if (t <= settle_end + 1e-9) {
      settle_sq += d.squaredNorm();
      settle_n += d.size();
    }
    row.pos_max = std::max(row.pos_max, d.maxCoeff());
    fsq += f * f;
    frsq += ref.trace.force[k].squaredNorm();
    ++row.compared;
    last = static_cast<int>(k);
    series.row("%d,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g", row.collisions ? 1 : 0, 1e3 * row.dt, t,
               1e3 * std::sqrt(d.squaredNorm() / static_cast<double>(d.size())), 1e3 * d.maxCoeff(), f,
               ref.trace.force[k].norm());
  }
  if (n == 0) return;
  row.pos_rms = std::sqrt(sq / static_cast<double>(n));
  if (settle_n > 0) row.settle_rms = std::sqrt(settle_sq / static_cast<double>(settle_n));
  row.force_rms = std::sqrt(fsq / row.compared);
  row.force_ref_rms = std::sqrt(frsq / row.compared);
  const Eigen::VectorXd d = (row.trace.x[static_cast<std::size_t>(last)] -
                             ref.trace.x[static_cast<std::size_t>(last)]).colwise().norm();
  row.end_rms = std::sqrt(d.squaredNorm() / static_cast<double>(d.size()));
  row.end_max = d.maxCoeff();
}

void timestep_table(const Config& cfg) {
  std::printf("\n1. Time step against a dt = %.2f ms reference: scripted probe run of %.1f s, default model (implicit "
              "Euler, n = 10);\n   intestine points (row 0, %d masses) compared every %.0f ms where the step lands "
              "on it, and at the end\n", 1e3 * cfg.reference_dt, cfg.duration, IntestineParams{}.columns,
              1e3 * kComparePeriod);
  CsvOut csv(cfg.out, "intestine_timestep",
             "self_collisions,dt_ms,steps,compared_times,step_us_p50,step_us_p99,cpu_s_per_sim_s,pos_rms_error_mm,"
             "pos_max_error_mm,end_rms_error_mm,end_max_error_mm,settle_rms_error_mm,force_rms_error_n,"
             "force_ref_rms_n,faults,stable");
  CsvOut series(cfg.series ? cfg.out : std::string(), "intestine_timestep_series",
                "self_collisions,dt_ms,t_s,pos_rms_error_mm,pos_max_error_mm,force_error_n,force_ref_n");
  std::printf("%-10s %8s %7s %9s %9s %10s %9s %9s %9s %9s %10s %9s %9s %6s\n", "collisions", "dt ms", "steps",
              "cpu p50us", "cpu p99us", "cpu s/sim s", "rms mm", "max mm", "end rms", "end max", "settle rms",
              "F rms N", "F ref N", "stable");
  for (const bool collisions : {false, true}) {
    char label[96];
    std::snprintf(label, sizeof label, "time step: reference dt = %.2f ms, self-collisions %s", 1e3 * cfg.reference_dt,
                  collisions ? "on" : "off");
    progress(label);
    const TimestepRow ref = run_timestep(cfg.reference_dt, collisions, cfg.duration);
    std::vector<double> dts{cfg.reference_dt};
    dts.insert(dts.end(), cfg.dts.begin(), cfg.dts.end());
    for (const double dt : dts) {
      TimestepRow row = dt == cfg.reference_dt ? ref : run_timestep(dt, collisions, cfg.duration);
      compare_with(row, ref, series);
      const RunResult& r = row.run;
      double cpu_total = 0;
      for (const double c : r.cpu) cpu_total += c;
      const double cpu_per_sim = 1e-6 * cpu_total / cfg.duration;
      const int steps = static_cast<int>(r.cpu.size());
      std::printf("%-10s %8.2f %7d %9.1f %9.1f %10.3f %9.3f %9.3f %9.3f %9.3f %10.4f %9.4f %9.4f %6s\n",
                  collisions ? "on" : "off", 1e3 * dt, steps, percentile(r.cpu, 0.5), percentile(r.cpu, 0.99),
                  cpu_per_sim, 1e3 * row.pos_rms, 1e3 * row.pos_max, 1e3 * row.end_rms, 1e3 * row.end_max,
                  1e3 * row.settle_rms, row.force_rms, row.force_ref_rms, row.stable ? "yes" : "NO");
      csv.row("%d,%.6g,%d,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%d,%d", collisions ? 1 : 0, 1e3 * dt,
              steps, row.compared, percentile(r.cpu, 0.5), percentile(r.cpu, 0.99), cpu_per_sim, 1e3 * row.pos_rms,
              1e3 * row.pos_max, 1e3 * row.end_rms, 1e3 * row.end_max, 1e3 * row.settle_rms, row.force_rms,
              row.force_ref_rms, r.faults, row.stable ? 1 : 0);
      std::fflush(stdout);
    }
  }
  std::printf("rms / max: over the compared times and the intestine's points; end: at the last time; settle: rms "
              "before the probe starts (%.2f s: gravity alone, smooth);\nF: probe force on the tool (N, clamped), "
              "error against the reference and the reference's own rms; cpu: the step's "
              "thread CPU time (us), and per simulated second (s). With self-collisions the random pairs make every "
              "run a different sample of the contacts, so the error there includes that spread.\n", probe_start());
}

// ---------------------------------------------------------------------------------------------------------------
// 2. Random pairs n against recall and time per step.

void pairs_table(const Config& cfg) {
  const int steps = static_cast<int>(std::lround(cfg.duration / 1e-3));
  std::printf("\n2. Random pairs n against the brute-force reference: scripted run of %.1f s at dt = 1 ms, compared "
              "every %d step(s) on the same positions\n", cfg.duration, cfg.compare_every);
  CsvOut csv(cfg.out, "intestine_pairs",
             "random_pairs,steps,compared_steps,pair_recall,region_recall,depth_recall,max_missed_mm,residual_mm,"
             "onsets,detect_steps_mean,detect_steps_p50,detect_steps_p90,detect_steps_max,undetected_fraction,"
             "contacts_mean,step_us_p50,step_us_p99,detect_us_p50,detect_us_p99");
  std::printf("%6s %7s %7s %7s %7s %7s %9s %8s %7s %8s %6s %6s %6s %8s %9s %9s\n", "n", "pairs", "ii", "im", "zones",
              "depth", "missed mm", "left mm", "onsets", "det mean", "p50", "p90", "max", "undetect", "cpu p50us",
              "cpu p99us");
  for (const int n : cfg.pairs) {
    char label[64];
    std::snprintf(label, sizeof label, "random pairs n = %d", n);
    progress(label);
    IntestineParams p;
    p.detector = CollisionDetector::kStochastic;
    p.detection.random_pairs = p.detection.random_mesentery_pairs = n;
    const RunResult r = scripted_run(p, steps, cfg.compare_every);
    double mean = 0;
    for (const double d : r.detect_steps) mean += d;
    if (!r.detect_steps.empty()) mean /= static_cast<double>(r.detect_steps.size());
    const double undetected = r.onsets > 0 ? static_cast<double>(r.undetected) / static_cast<double>(r.onsets) : 0.0;
    const double p50 = percentile(r.detect_steps, 0.5), p90 = percentile(r.detect_steps, 0.9);
    const double dmax = percentile(r.detect_steps, 1.0);
    std::printf("%6d %7.3f %7.3f %7.3f %7.3f %7.3f %9.2f %8.2f %7ld %8.2f %6.0f %6.0f %6.0f %8.3f %9.1f %9.1f\n", n,
                r.recall.pair_recall(), r.recall_kind[0].pair_recall(), r.recall_kind[1].pair_recall(),
                r.recall.region_recall(), r.recall.depth_recall(), 1e3 * r.recall.max_missed,
                1e3 * r.residual, r.onsets, mean, p50, p90, dmax, undetected, percentile(r.cpu, 0.5),
                percentile(r.cpu, 0.99));
    csv.row("%d,%d,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%ld,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g", n, steps,
            r.compared, r.recall.pair_recall(), r.recall.region_recall(), r.recall.depth_recall(),
            1e3 * r.recall.max_missed, 1e3 * r.residual, r.onsets, mean, p50, p90, dmax, undetected, r.contacts_mean,
            percentile(r.cpu, 0.5), percentile(r.cpu, 0.99), percentile(r.detection, 0.5),
            percentile(r.detection, 0.99));
    std::fflush(stdout);
  }
  std::printf("pairs: reference contacts the detector reported at the same step (ii: intestine-intestine, im: "
              "intestine-mesentery contacts alone); zones: contact zones with one "
              "reported; depth: weighted by penetration;\nmissed: deepest reference contact not reported; left: "
              "deepest penetration after the response; onsets: reference contacts appearing; det: steps until the "
              "detector\nreports an onset (mean, p50, p90, max); undetect: onsets that left the reference unreported; "
              "cpu: the step's thread CPU time, us.\n");
}

// ---------------------------------------------------------------------------------------------------------------
// 3. Level of detail against geometric error and frame time.

// The skinned surface of one interval, the limit of the LODs: S(a, t) = (1 - w(t)) A v + w(t) B v with
// v = (cos a, sin a, t, 1) and A, B the interval's matrices (TubeMesh::skin, tube_geometry.h).
struct IntervalSurface {
  Eigen::Matrix<double, 3, 4> A, B;

  IntervalSurface(const float* m) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) {
        A(r, c) = m[4 * r + c];
        B(r, c) = m[12 + 4 * r + c];
      }
    }
  }
  Eigen::Vector3d at(double a, double t) const {
    const double w = skin_weight(t);
    const Eigen::Vector4d v(std::cos(a), std::sin(a), t, 1);
    return (1 - w) * (A * v) + w * (B * v);
  }
  // Distance from p to the surface: Gauss-Newton on (a, t) from the guess, t kept in [0, 1].
  double distance(const Eigen::Vector3d& p, double a, double t) const {
    for (int it = 0; it < 6; ++it) {
      const double w = skin_weight(t), dw = 6 * t * (1 - t);
      const Eigen::Vector4d v(std::cos(a), std::sin(a), t, 1);
      const Eigen::Matrix<double, 3, 4> M = (1 - w) * A + w * B;
      const Eigen::Vector3d r = p - M * v;
      Eigen::Matrix<double, 3, 2> J;
      J.col(0) = M * Eigen::Vector4d(-std::sin(a), std::cos(a), 0, 0);
      J.col(1) = dw * ((B - A) * v) + M.col(2);
      const Eigen::Vector2d step = (J.transpose() * J).ldlt().solve(J.transpose() * r);
      if (!step.allFinite()) break;
      a += step[0];
      t = std::clamp(t + step[1], 0.0, 1.0);
    }
    return (p - at(a, t)).norm();
  }
};

struct GeometricError {
  double max = 0, sum_sq = 0;
  long samples = 0;
  double vertex_check = 0;  // m, largest gap between the built mesh's vertices and the surface formula
  double rms() const { return samples > 0 ? std::sqrt(sum_sq / static_cast<double>(samples)) : 0.0; }
};

// Chordal error of the LOD the mesh was built at: each flat triangle of each interval (the primitive's tube part)
// sampled at 7 interior points, each point's distance to the interval's skinned surface. Also checks that the
// mesh's vertices are the surface at the primitive's parameters (the layout this measure assumes).
void measure_lod(const TubeBuilder& builder, const TubeMesh& mesh, int lod, GeometricError& e) {
  const TubePrimitive& prim = builder.primitive(lod);
  const TubeLod l = tube_lod(lod);
  const int body = (l.rings + 1) * l.sides;  // the primitive's tube vertices come first (then any end caps)
  auto param = [&](std::uint32_t i, double& a, double& t) {
    a = std::atan2(prim.vertices[4 * i + 1], prim.vertices[4 * i]);
    t = prim.vertices[4 * i + 2];
  };
  static constexpr std::array<std::array<double, 3>, 7> kBary{{{1 / 3.0, 1 / 3.0, 1 / 3.0},
                                                               {0.5, 0.5, 0},
                                                               {0, 0.5, 0.5},
                                                               {0.5, 0, 0.5},
                                                               {2 / 3.0, 1 / 6.0, 1 / 6.0},
                                                               {1 / 6.0, 2 / 3.0, 1 / 6.0},
                                                               {1 / 6.0, 1 / 6.0, 2 / 3.0}}};
  for (int k = 0; k < mesh.intervals; ++k) {
    const IntervalSurface surf(&mesh.skin[static_cast<std::size_t>(24 * k)]);
    // Vertex check: ring j of this interval is ring k rings + j of the mesh (ring-major, `sides` per ring).
    for (int j = 0; j <= l.rings; ++j) {
      for (int i = 0; i < l.sides; ++i) {
        double a = 0, t = 0;
        param(static_cast<std::uint32_t>(j * l.sides + i), a, t);
        const std::size_t vi = 3 * static_cast<std::size_t>((k * l.rings + j) * l.sides + i);
        const Eigen::Vector3d built(mesh.positions[vi], mesh.positions[vi + 1], mesh.positions[vi + 2]);
        e.vertex_check = std::max(e.vertex_check, (built - surf.at(a, t)).norm());
      }
    }
    for (std::size_t f = 0; f + 2 < prim.indices.size(); f += 3) {
      const std::uint32_t* tri = &prim.indices[f];
      if (tri[0] >= static_cast<std::uint32_t>(body) || tri[1] >= static_cast<std::uint32_t>(body) ||
          tri[2] >= static_cast<std::uint32_t>(body)) {
        continue;  // an end cap
      }
      double a[3], t[3];
      Eigen::Vector3d v[3];
      for (int c = 0; c < 3; ++c) {
        param(tri[c], a[c], t[c]);
        // Angles on one branch with the first vertex's (the seam at a = pi).
        if (c > 0) a[c] += 2 * M_PI * std::round((a[0] - a[c]) / (2 * M_PI));
        v[c] = surf.at(a[c], t[c]);
      }
      for (const auto& b : kBary) {
        const Eigen::Vector3d p = b[0] * v[0] + b[1] * v[1] + b[2] * v[2];
        const double d = surf.distance(p, b[0] * a[0] + b[1] * a[1] + b[2] * a[2],
                                       b[0] * t[0] + b[1] * t[1] + b[2] * t[2]);
        e.max = std::max(e.max, d);
        e.sum_sq += d * d;
        ++e.samples;
      }
    }
  }
}

// Body states of the scripted run (dt = 1 ms): `count` of them, evenly spread from 0.4 s (the folds have settled and
// the probe starts) to the end.
std::vector<std::vector<double>> body_states(int count, double duration) {
  const IntestineParams params;
  const int steps = static_cast<int>(std::lround(duration / 1e-3));
  const int first = std::min(400, steps - 1);
  std::vector<int> at;
  for (int i = 0; i < count; ++i) at.push_back(first + (steps - 1 - first) * i / std::max(count - 1, 1));
  std::vector<std::vector<double>> states;
  scripted_run(params, steps, 0, 1e-3, [&](int s, const IntestineState& state, const StepReport&) {
    if (std::find(at.begin(), at.end(), s) != at.end())
      states.emplace_back(state.positions(), state.positions() + 3 * state.point_count());
  });
  return states;
}

// The intestine scene drawn with a tube of a fixed LOD, skinned on the CPU: the mesentery over the whole grid (two
// triangles per cell) and the tube's triangles (end caps included when the builder makes them).
class LodScene {
 public:
  LodScene(int rows, int cols, int max_points)
      : rows_(rows), cols_(cols), builder_(TubeParams{}, max_points), mesh_(builder_.make_mesh(kTubeMaxLod)) {
    mesentery_.resize(rows * cols, 3);
    mesentery_tris_.resize(2 * (rows - 1) * (cols - 1), 3);
    int f = 0;
    for (int r = 0; r + 1 < rows; ++r) {
      for (int c = 0; c + 1 < cols; ++c) {
        const int a = r * cols + c, b = a + 1, d = a + cols, e = d + 1;
        mesentery_tris_.row(f++) << a, b, e;
        mesentery_tris_.row(f++) << a, e, d;
      }
    }
    tube_.resize(static_cast<Eigen::Index>(mesh_.positions.size() / 3), 3);
    tube_tris_.resize(static_cast<Eigen::Index>(mesh_.indices.size() / 3), 3);
  }
  /// Builds the tube at `lod` through the body state's intestine points; false if the builder refused it.
  bool build(const std::vector<double>& x, int lod) {
    if (!builder_.build(x.data(), cols_, lod, mesh_)) return false;
    for (int v = 0; v < mesh_.vertex_count; ++v) {
      for (int c = 0; c < 3; ++c) tube_(v, c) = mesh_.positions[3 * static_cast<std::size_t>(v) + c];
    }
    for (int t = 0; t < mesh_.index_count / 3; ++t) {
      for (int c = 0; c < 3; ++c) {
        tube_tris_(t, c) = static_cast<int>(mesh_.indices[3 * static_cast<std::size_t>(t) + c]);
      }
    }
    for (int n = 0; n < rows_ * cols_; ++n) {
      for (int c = 0; c < 3; ++c) mesentery_(n, c) = static_cast<float>(x[3 * static_cast<std::size_t>(n) + c]);
    }
    return true;
  }
  void draw(surgsim::Renderer& renderer) const {
    renderer.draw_surface(mesentery_, mesentery_tris_, surgsim::kMesenteryRgb);
    renderer.draw_surface(tube_.topRows(mesh_.vertex_count), tube_tris_.topRows(mesh_.index_count / 3),
                          surgsim::kIntestineRgb);
  }
  const TubeBuilder& builder() const { return builder_; }
  const TubeMesh& mesh() const { return mesh_; }

 private:
  int rows_, cols_;
  TubeBuilder builder_;
  TubeMesh mesh_;
  Eigen::MatrixX3f mesentery_, tube_;
  Eigen::MatrixX3i mesentery_tris_, tube_tris_;
};

void lod_table(const Config& cfg, const std::vector<std::vector<double>>& states) {
  const IntestineParams params;
  const double radius = TubeParams{}.radius;
  std::printf("\n3. Level of detail against geometric error and frame time: %zu body states of the scripted run; "
              "error of the flat triangles (7 samples each) against\n   the skinned surface they approximate (the "
              "limit of infinitely many sides and rings), tube radius %.0f mm; frames at %d x %d, CPU skinning\n",
              states.size(), 1e3 * radius, cfg.width, cfg.height);
  CsvOut csv(cfg.out, "intestine_lod",
             "lod,sides,rings,intervals_mean,vertices_mean,triangles_mean,geom_max_error_mm,geom_rms_error_mm,"
             "geom_max_error_pct_radius,geom_rms_error_pct_radius,vertex_check_mm,build_us_p50,build_us_p99,frames,"
             "render_ms_p50,render_ms_p99,frame_ms_p50,frame_ms_p99,renderer");
  std::unique_ptr<surgsim::Renderer> renderer;
  std::string renderer_name = "none";
  const surgsim::scene::Scene scene = surgsim::scene::load_scene(surgsim::scene::resolve_scene_path("intestine"));
  LodScene drawn(params.rows, params.columns, params.columns);
  if (cfg.render) {
    renderer = surgsim::make_renderer("osmesa", cfg.width, cfg.height);
    renderer_name = renderer->name();
  }
  std::printf("%-4s %-8s %9s %10s %10s %10s %8s %9s %9s %10s %10s\n", "LOD", "sides x r", "triangles", "max mm",
              "rms mm", "max % r", "build us", "render ms", "frame ms", "frame p99", "check mm");
  TubeBuilder builder(TubeParams{}, params.columns);
  TubeMesh mesh = builder.make_mesh(kTubeMaxLod);
  for (int lod = 0; lod <= kTubeMaxLod; ++lod) {
    char label[64];
    std::snprintf(label, sizeof label, "LOD %d", lod);
    progress(label);
    const TubeLod l = tube_lod(lod);
    GeometricError e;
    std::vector<double> build_us;
    double intervals = 0, vertices = 0, triangles = 0;
    for (const auto& x : states) {
      builder.reset_frames();
      const double c0 = thread_cpu_us();
      const bool ok = builder.build(x.data(), params.columns, lod, mesh);
      build_us.push_back(thread_cpu_us() - c0);
      if (!ok) continue;
      intervals += mesh.intervals;
      vertices += mesh.vertex_count;
      triangles += mesh.index_count / 3;
      measure_lod(builder, mesh, lod, e);
    }
    const double count = std::max<double>(1, static_cast<double>(states.size()));
    // Frames: each draws the next body state (the tube rebuilt, as on a new BodyState), after one warm-up frame.
    std::vector<double> render_ms, frame_ms;
    for (int f = -1; renderer && f < cfg.lod_frames; ++f) {
      const auto& x = states[static_cast<std::size_t>(std::max(f, 0)) % states.size()];
      const auto t0 = WallClock::now();
      drawn.build(x, lod);
      const auto t1 = WallClock::now();
      renderer->begin_frame(scene.visual.camera);
      drawn.draw(*renderer);
      renderer->end_frame();
      if (f < 0) continue;
      render_ms.push_back(1e-3 * us_since(t1));
      frame_ms.push_back(1e-3 * us_since(t0));
    }
    std::printf("%-4d %2d x %-3d %9.0f %10.4f %10.4f %10.3f %8.0f %9.2f %9.2f %10.2f %10.2g\n", lod, l.sides, l.rings,
                triangles / count, 1e3 * e.max, 1e3 * e.rms(), 100 * e.max / radius, percentile(build_us, 0.5),
                percentile(render_ms, 0.5), percentile(frame_ms, 0.5), percentile(frame_ms, 0.99),
                1e3 * e.vertex_check);
    csv.row("%d,%d,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%zu,%.6g,%.6g,%.6g,%.6g,%s", lod, l.sides,
            l.rings, intervals / count, vertices / count, triangles / count, 1e3 * e.max, 1e3 * e.rms(),
            100 * e.max / radius, 100 * e.rms() / radius, 1e3 * e.vertex_check, percentile(build_us, 0.5),
            percentile(build_us, 0.99), frame_ms.size(), percentile(render_ms, 0.5), percentile(render_ms, 0.99),
            percentile(frame_ms, 0.5), percentile(frame_ms, 0.99), renderer_name.c_str());
    std::fflush(stdout);
  }
  std::printf("max / rms: distance (mm) of triangle samples to the skinned surface, and max as %% of the radius; "
              "build: spline, frames, guard and CPU skinning (thread CPU, us);\nrender: begin..end of the frame "
              "(OSMesa %s, wall clock); frame: build + copy + render; check: vertices against the surface formula "
              "(float rounding).\n", renderer_name.c_str());
}

// ---------------------------------------------------------------------------------------------------------------
// 4. The frame-rate controller on the real renderer.

void frame_rate_table(const Config& cfg, const std::vector<std::vector<double>>& states) {
  // The gains IntestineView runs with: FrameRateParams' defaults (the error in octaves, not the paper's Hz).
  const surgsim::intestine::FrameRateParams gains;
  std::printf("\n4. Frame-rate controller (eq. 15 with e = %s, alpha = %g, beta = %g) in the visual node's "
              "IntestineView on OSMesa at %d x %d: %d frames per target, each a new body state;\n   rate = 1 / mean work "
              "time (tube build + draw + end of frame, what the controller is fed), statistics over the second half\n",
              gains.error == surgsim::intestine::FrameRateError::kHz ? "f0 - f (Hz)" : "log2(f0 / f)", gains.alpha,
              gains.beta, cfg.width, cfg.height, cfg.controller_frames);
  CsvOut csv(cfg.out, "intestine_frame_rate",
             "target_fps,frames,fps_mean,work_ms_p50,work_ms_p99,lod_mean,lod_min,lod_max,lod_final,frames_to_settle,"
             "samples,triangles_mean,renderer,skinning");
  surgsim::scene::Scene scene = surgsim::scene::load_scene(surgsim::scene::resolve_scene_path("intestine"));
  auto renderer = surgsim::make_renderer("osmesa", cfg.width, cfg.height);
  std::string skinning_used = "cpu";
  std::printf("%-10s %8s %9s %9s %9s %8s %8s %9s %8s %9s\n", "target Hz", "mean Hz", "work p50", "work p99", "LOD mean",
              "LOD used", "settled", "samples", "final", "triangles");
  for (const double target : cfg.targets) {
    char label[64];
    std::snprintf(label, sizeof label, "frame-rate controller at %.0f Hz", target);
    progress(label);
    scene.visual.target_fps = target;
    surgsim::IntestineView view(scene, scene.hash());
    const int frames = cfg.controller_frames, from = frames / 2;
    std::vector<double> work_ms;
    std::vector<int> lods;
    double lod_sum = 0, tri_sum = 0;
    int lod_min = kTubeMaxLod, lod_max = 0;
    for (int f = 0; f < frames; ++f) {
      const auto& x = states[static_cast<std::size_t>(f) % states.size()];
      const auto t0 = WallClock::now();
      view.set_positions(x.data(), static_cast<int>(x.size() / 3));
      const int lod = view.lod();
      renderer->begin_frame(scene.visual.camera);
      view.draw(*renderer);
      renderer->end_frame();
      const double work = us_since(t0);
      view.frame_done(1e-6 * work);
      lods.push_back(lod);
      if (f < from) continue;
      work_ms.push_back(1e-3 * work);
      lod_sum += lod;
      tri_sum += view.tube_triangles();
      lod_min = std::min(lod_min, lod);
      lod_max = std::max(lod_max, lod);
    }
    // Frames until the LOD stays inside the range used over the second half.
    int settle = 0;
    for (int f = 0; f < frames; ++f) {
      if (lods[static_cast<std::size_t>(f)] < lod_min || lods[static_cast<std::size_t>(f)] > lod_max) settle = f + 1;
    }
    double work_mean = 0;
    for (const double w : work_ms) work_mean += w;
    const double n = std::max<double>(1, static_cast<double>(work_ms.size()));
    work_mean /= n;
    const nlohmann::json st = view.stats();
    const int samples = st["tube_last"]["samples"].get<int>();
    const std::string skinning = st.value("tube_skinning", std::string("cpu"));
    skinning_used = skinning == "gpu" ? "GPU" : "CPU";
    char used[16];
    std::snprintf(used, sizeof used, lod_min == lod_max ? "%d" : "%d-%d", lod_min, lod_max);
    std::printf("%-10.0f %8.1f %9.2f %9.2f %9.2f %8s %8d %9d %8d %9.0f\n", target, 1e3 / work_mean,
                percentile(work_ms, 0.5), percentile(work_ms, 0.99), lod_sum / n, used, settle, samples, view.lod(),
                tri_sum / n);
    csv.row("%.6g,%d,%.6g,%.6g,%.6g,%.6g,%d,%d,%d,%d,%d,%.6g,%s,%s", target, frames, 1e3 / work_mean,
            percentile(work_ms, 0.5), percentile(work_ms, 0.99), lod_sum / n, lod_min, lod_max, view.lod(), settle,
            samples, tri_sum / n, renderer->name(), skinning.c_str());
    std::fflush(stdout);
  }
  std::printf("mean Hz: 1 / mean work time over the second half; LOD used: range over the second half; settled: "
              "frames until the LOD stays in that range; samples: tube rings of the last build.\n"
              "The view skins the tube on the %s (its default).\n", skinning_used.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"intestine_error_bench: intestine error against run time (time step, random pairs, level of detail, "
               "frame-rate control); tables on stdout, progress on stderr, CSV files with --out"};
  Config cfg;
  bool quick = false, smoke = false, no_render = false;
  std::vector<std::string> only;
  app.add_option("--out", cfg.out, "write intestine_timestep.csv, intestine_pairs.csv, "
                                   "intestine_lod.csv and intestine_frame_rate.csv into this folder (made if missing)");
  app.add_flag("--series", cfg.series,
               "with --out, also intestine_timestep_series.csv: the errors at each compared time of each run (for "
               "plots of the error over time; thousands of lines)");
  app.add_flag("--quick", quick, "shorter runs (about a minute): 1.7 s scripted runs, fewer frames");
  app.add_flag("--smoke", smoke, "tiny configuration for the ctest (a few seconds; figures meaningless)");
  app.add_flag("--no-render", no_render, "skip OSMesa (LOD table without frame times, no controller table)");
  app.add_option("--only", only, "run only these tables: timestep, pairs, lod, frame_rate")
      ->check(CLI::IsMember({"timestep", "pairs", "lod", "frame_rate"}));
  app.add_option("--width", cfg.width, "frame width, pixels")->check(CLI::Range(16, 8192));
  app.add_option("--height", cfg.height, "frame height, pixels")->check(CLI::Range(16, 8192));
  CLI11_PARSE(app, argc, argv);

  cfg.dts = {0.25e-3, 0.5e-3, 1e-3, 2e-3, 5e-3, 10e-3, 1.0 / 30};
  cfg.pairs = {0, 1, 2, 5, 10, 20, 50, 100, 200};
  cfg.targets = {30, 60, 120};
  if (quick) {
    cfg.duration = 1.7;
    cfg.compare_every = 4;
    cfg.pairs = {0, 1, 2, 5, 10, 20, 50, 100};
    cfg.states = 20;
    cfg.lod_frames = 20;
    cfg.controller_frames = 200;
  }
  if (smoke) {
    cfg.duration = 0.6;
    cfg.reference_dt = 0.5e-3;
    cfg.dts = {1e-3, 2e-3, 10e-3};
    cfg.pairs = {0, 10};
    cfg.compare_every = 1;
    cfg.states = 3;
    cfg.lod_frames = 2;
    cfg.targets = {60};
    cfg.controller_frames = 10;
  }
  cfg.render = !no_render;
  auto want = [&](const char* table) {
    return only.empty() || std::find(only.begin(), only.end(), table) != only.end();
  };
  try {
    surgsim::bench::make_dirs(cfg.out);
    const auto t0 = WallClock::now();
    std::printf("intestine_error_bench (%s; CPU times are this thread's, frame times wall clock; 2-core shared "
                "machine)\n", smoke ? "smoke" : quick ? "quick" : "default");
    if (want("timestep")) timestep_table(cfg);
    if (want("pairs")) pairs_table(cfg);
    if (want("lod") || (cfg.render && want("frame_rate"))) {
      progress("body states for the LOD and frame-rate tables");
      const auto states = body_states(cfg.states, cfg.duration);
      if (want("lod")) lod_table(cfg, states);
      if (cfg.render && want("frame_rate")) frame_rate_table(cfg, states);
    }
    std::fprintf(stderr, "intestine_error_bench: done in %.1f s%s%s\n", 1e-6 * us_since(t0),
                 cfg.out.empty() ? "" : ", CSV in ", cfg.out.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "intestine_error_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
