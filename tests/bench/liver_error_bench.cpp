// liver_error_bench: the liver's error against run time. A plain program run by hand
// (build/bench/liver_error_bench --out DIR); readable tables on stdout, progress on stderr, and with --out one CSV
// per table (csv_out.h). --quick is the short run, --smoke the tiny configuration its ctest runs (box meshes, no Gmsh).
//
// The organ is the scene's (config/liver.yaml: generated liver at --nodes, E, nu, the clamped underside, the
// non-linear curves). Reference: the exact direct solve in double (StaticSolver, CHOLMOD) of the same frames.
//   1. Contact frames: a fixed, seeded set of frames with 1, 3 and 10 contact nodes (a patch of the nearest
//      contactable nodes around a random point of the top surface, all pushed by one displacement of 2-5 mm along
//      the inward normal plus up to 1 mm sideways). Per frame, each method's time and its errors:
//        full_solve       factor K_ff + Schur solve each frame (a simulator without precomputation);
//        prefactored      K_ff factored once, the Schur solve each frame;
//        cg               the paper's reference: CG (Jacobi) on the reduced system at tolerances 1e-2 .. 1e-8;
//        tensors_double   precomputed tensors: lambda = G_CC^-1 u* (haptic block) + every visible node's u (visual);
//        tensors_float    the same with float tensors;
//        tensors_dropped  far-field 3x3 blocks G(r, c) with |G(r, c)|_F < t |G(c, c)|_F dropped (t = thresholds);
//                         evaluated with those blocks zeroed, the visual part from a block-sparse copy (so the time
//                         is what a block-sparse store would pay); memory = block-sparse storage (72 B per kept block
//                         + a 4 B row index, both blocks).
//   2. Discretization: the liver meshed at --mesh-sizes, one physical load (a flat punch: every free top-surface node
//      within 2 cm in x-y of (0.03, 0) pushed 5 mm down) solved directly, against the finest mesh: total force, and
//      displacements at fixed sample points (300 seeded points 3 mm under the finest mesh's surface nodes above the
//      clamp, located by barycentric interpolation in each mesh: the containing tet, or the nearest one with clamped
//      coordinates; samples_outside counts the latter). The tensors are
//      precomputed on every mesh but the largest when it exceeds --max-precompute-nodes (the 20k one takes ~90 s and
//      4 GB): there the time per frame is the prefactored solve's.
//   3. Non-linear: the same punch at 5 .. 30 % of the organ's height (z extent), linear tensors, quasi non-linear
//      (tensors + the law as the nodes apply it: Q on the tool force along the mean imposed displacement, as
//      haptic_node/liver_contacts.cpp; P on every visible row along the direction of the summed contact rows, as
//      visual_node/views/surface_deformer.cpp) against the neo-Hookean Newton reference (common/fem/hyperelastic.h).
//
// Errors: disp = |u - u_ref|_2 / |u_ref|_2 over the visible (boundary) nodes (stacked x, y, z); force =
// |F - F_ref| / |F_ref| of the total contact force (vectors). In the summary a method's error is its worst frame.
// Time per frame: wall clock, microseconds, median (p50) and 99th percentile (bench_util.h: nearest rank below) over
// all frames x repeats.
// Far-field note: the visual rows include the clamped boundary nodes, whose blocks are exactly zero; any threshold
// drops those first.
//
// CSV files (with --out DIR; units in the column names; an empty cell = not measured):
//   liver_error_time.csv        family,variant,time_per_frame_us_p50,time_per_frame_us_p99,disp_rel_error,
//                               force_rel_error,memory_mib
//       one row per method: families full_solve, prefactored, cg (variant tol_1e-06 ...), tensors_double,
//       tensors_float, tensors_dropped (variant thr_1e-03 ...), mesh (variant nodes_<N>_tensors | nodes_<N>_solve:
//       which time it is; errors against the finest mesh, disp at the sample points), linear_vs_nonlinear (variants
//       linear_<p>pct, quasi_<p>pct, newton_<p>pct: errors against Newton, Newton's time is its whole solve).
//       memory_mib: what the method keeps between frames (tensors; CHOLMOD factor; K_ff for CG and the full solve;
//       for the mesh family the tensors, estimated when not precomputed).
//   liver_error_frames.csv      family,variant,contacts,frames,time_per_frame_us_p50,time_per_frame_us_p99,
//                               disp_rel_error_max,disp_rel_error_median,force_rel_error_max,cg_iterations_max
//   liver_error_dropped.csv     threshold_rel,blocks_kept_fraction,memory_dense_mib,memory_sparse_mib,saved_fraction,
//                               saved_mib,disp_rel_error,force_rel_error,time_per_frame_us_p50
//   liver_mesh_convergence.csv  nodes,tets,visible_nodes,indenter_nodes,force_n,force_rel_error,disp_rel_error,
//                               samples_outside,factor_ms,solve_ms,precompute_s,tensor_mib,tensor_frame_us_p50,
//                               tensor_frame_us_p99
//   liver_nonlinear.csv         indentation_percent,indentation_mm,indenter_nodes,newton_force_n,linear_force_n,
//                               quasi_force_n,linear_force_rel_error,quasi_force_rel_error,linear_disp_rel_error,
//                               quasi_disp_rel_error,newton_converged,newton_load_steps,newton_iterations,newton_ms,
//                               linear_frame_us_p50,quasi_frame_us_p50,q_extrapolated
//       (newton_converged 1/0; forces are the tool force's magnitude, N; q_extrapolated 1 when the linear force is
//       beyond the range Q was fitted on, where the law continues along its end tangent.)
//
// Run time on the 2-core development VM: default about 45 s with the meshes cached (about 70 s when it meshes them
// first, the 20k-node liver included), --quick about 25 s, --smoke about 1 s.
#include <CLI/CLI.hpp>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "bench_util.h"
#include "liver_bench_organ.h"
#include "mesh/box_mesh.h"
#include "csv_out.h"
#include "core/error.h"
#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "fem/hyperelastic.h"
#include "nonlinear/nonlinear_law.h"
#include "compliance/precompute.h"
#include "scene/scene.h"
#include "fem/static_solver.h"
#include "compliance/superposition.h"
#include "mesher/scene_mesh.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::scene;
using namespace surgsim::mesher;

namespace {

using namespace surgsim;
using bench::CsvOut;
using namespace surgsim::bench_liver;

constexpr double kMiB = 1024.0 * 1024.0;
constexpr double kMeshPunchDepth = 0.005;       // m
constexpr double kSampleDepth = 0.003;          // m, sample points under the finest mesh's surface

struct Settings {
  std::string scene = "liver";
  std::string out, cache;
  int nodes = 1500;
  std::vector<int> mesh_sizes = {500, 1500, 5000, 20000};
  int max_precompute_nodes = 8000;
  std::vector<int> contact_counts = {1, 3, 10};
  int frames = 12;              // per contact count
  int tensor_repeats = 200;     // per frame
  int solve_repeats = 3;        // per frame (direct)
  int cg_repeats = 1;           // per frame
  std::vector<double> cg_tols = {1e-2, 1e-4, 1e-6, 1e-8};
  std::vector<double> drop_thresholds = {1e-4, 1e-3, 1e-2, 3e-2, 1e-1};
  std::vector<double> indentations = {5, 10, 15, 20, 25, 30};  // % of the organ's height
  unsigned seed = 7;
  bool smoke = false;
};

void progress(const std::string& what) { std::cerr << "liver_error_bench: " << what << std::endl; }

using Clock = bench::WallClock;
using bench::us_since;

PrecomputeOptions precompute_options(Precision precision) {
  PrecomputeOptions opts;
  opts.precision = precision;
  opts.memory_limit_mb = 0;
  return opts;
}

// ---- measurements ------------------------------------------------------------------------------------------------

// One method's samples, by contact count.
struct Measure {
  Measure(std::string f, std::string v, double mib) : family(std::move(f)), variant(std::move(v)), memory_mib(mib) {}
  std::string family, variant;
  double memory_mib = 0;  // what the method keeps between frames
  std::map<int, std::vector<double>> time_us, disp_error, force_error;
  std::map<int, int> cg_iterations_max;
  std::vector<double> all_times() const {
    std::vector<double> t;
    for (const auto& [m, v] : time_us) t.insert(t.end(), v.begin(), v.end());
    return t;
  }
  double worst(const std::map<int, std::vector<double>>& e) const {
    double w = 0;
    for (const auto& [m, v] : e)
      for (double x : v) w = std::max(w, x);
    return w;
  }
};

// A row of liver_error_time.csv.
struct SummaryRow {
  std::string family, variant;
  double p50 = 0, p99 = 0, disp = 0, force = 0, memory_mib = 0;
};

// A contact frame and its reference solution.
struct Frame {
  int m = 0;
  std::vector<Contact> contacts;
  std::vector<ImposedDisplacement> imposed;
  Eigen::VectorXd ref_visible;      // 3R, m
  Eigen::Vector3d ref_tool_force;   // N
};

std::vector<Frame> make_frames(const Organ& o, const Settings& s, StaticSolver& reference) {
  std::mt19937 rng(s.seed);
  std::vector<int> top;
  for (int k : o.contacts)
    if (o.normals(k, 2) > 0.5) top.push_back(k);
  if (top.empty()) throw Error("no contactable node on the top surface");
  std::uniform_int_distribution<std::size_t> pick(0, top.size() - 1);
  std::uniform_real_distribution<double> depth(0.002, 0.005), side(-0.001, 0.001);
  std::vector<Frame> frames;
  for (int m : s.contact_counts)
    for (int f = 0; f < s.frames; ++f) {
      const int c0 = top[pick(rng)];
      const Eigen::Vector3d n = o.normals.row(c0).transpose();
      Eigen::Vector3d d = -depth(rng) * n + Eigen::Vector3d(side(rng), side(rng), side(rng));
      std::vector<std::pair<double, int>> by_distance;
      for (int k : o.contacts) by_distance.emplace_back((o.mesh.nodes.row(k) - o.mesh.nodes.row(c0)).norm(), k);
      const int take = std::min<int>(m, static_cast<int>(by_distance.size()));
      std::partial_sort(by_distance.begin(), by_distance.begin() + take, by_distance.end());
      Frame fr;
      fr.m = take;
      for (int i = 0; i < take; ++i) {
        const int k = by_distance[static_cast<std::size_t>(i)].second;
        fr.contacts.push_back({k, d});
        fr.imposed.push_back({k, d, 7});
      }
      const StaticSolution ref = reference.solve(fr.imposed);
      fr.ref_visible = visible_part(o, ref.displacement);
      fr.ref_tool_force = -ref.total_reaction;
      frames.push_back(std::move(fr));
    }
  return frames;
}

// Runs `eval(frame, u_visible, tool_force)` `repeats` times per frame (the last result is scored).
template <typename Eval>
void measure(Measure& out, const std::vector<Frame>& frames, int repeats, Eval&& eval) {
  Eigen::VectorXd u;
  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  for (const Frame& fr : frames) {
    for (int r = 0; r < repeats; ++r) {
      const auto t0 = Clock::now();
      eval(fr, u, force);
      out.time_us[fr.m].push_back(us_since(t0));
    }
    out.disp_error[fr.m].push_back(rel((u - fr.ref_visible).norm(), fr.ref_visible.norm()));
    out.force_error[fr.m].push_back(rel((force - fr.ref_tool_force).norm(), fr.ref_tool_force.norm()));
  }
}

// Tensor evaluation of one frame: the haptic solve (lambda, tool force), then every visible node's displacement.
struct TensorEvaluator {
  Superposition haptic;
  Superposition visual;
  ContactSolution sol;
  TensorEvaluator(const Tensors& t) : haptic(t, "haptic"), visual(t, "visual") {}
  bool operator()(const Contact* contacts, int m, Eigen::VectorXd& u, Eigen::Vector3d& force) {
    u.resize(3 * visual.block().row_count());
    if (haptic.solve(contacts, m, sol) != ContactStatus::kOk) return false;
    force = sol.tool_force;
    return visual.displacements(sol.nodes.data(), sol.lambda.data(), sol.count, u) == ContactStatus::kOk;
  }
};

std::size_t sparse_bytes(const Eigen::SparseMatrix<double>& a) {
  return static_cast<std::size_t>(a.nonZeros()) * (sizeof(double) + sizeof(int)) +
         static_cast<std::size_t>(a.outerSize() + 1) * sizeof(int);
}

// The visual block kept as 3x3 blocks per column (far-field blocks dropped), and its evaluation.
struct SparseVisual {
  std::vector<int> start;                // #S + 1
  std::vector<int> row;                  // kept blocks: row index r (node visible[r])
  std::vector<Eigen::Matrix3d> g;        // kept blocks, m/N
  const Tensors* tensors = nullptr;
  int rows = 0;
  void displacements(const int* nodes, const Eigen::Vector3d* lambda, int m, Eigen::VectorXd& u) const {
    u.setZero(3 * rows);
    for (int l = 0; l < m; ++l) {
      const int c = tensors->column_of_node[static_cast<std::size_t>(nodes[l])];
      for (int b = start[static_cast<std::size_t>(c)]; b < start[static_cast<std::size_t>(c) + 1]; ++b)
        u.segment<3>(3 * row[static_cast<std::size_t>(b)]).noalias() += g[static_cast<std::size_t>(b)] * lambda[l];
    }
  }
};

// Drops the blocks of `t` (double) below threshold x the norm of their column's diagonal block, in place; fills the
// block-sparse copy of the visual block. Returns the number of kept blocks over both blocks.
std::size_t drop_far_field(Tensors& t, double threshold, SparseVisual& sv) {
  const TensorBlock* haptic = t.find("haptic");
  std::vector<double> diag(static_cast<std::size_t>(t.column_count()));
  for (int c = 0; c < t.column_count(); ++c)
    diag[static_cast<std::size_t>(c)] = haptic->block3(haptic->row_of_node[static_cast<std::size_t>(t.contact_nodes[static_cast<std::size_t>(c)])], c).norm();
  std::size_t kept = 0;
  for (TensorBlock& b : t.blocks) {
    const bool visual = b.name == "visual";
    if (visual) {
      sv = SparseVisual();
      sv.tensors = &t;
      sv.rows = b.row_count();
      sv.start.push_back(0);
    }
    for (int c = 0; c < t.column_count(); ++c) {
      for (int r = 0; r < b.row_count(); ++r) {
        auto blk = b.g.block<3, 3>(3 * r, 3 * c);
        if (blk.norm() < threshold * diag[static_cast<std::size_t>(c)]) {
          blk.setZero();
          continue;
        }
        ++kept;
        if (visual) {
          sv.row.push_back(r);
          sv.g.push_back(blk);
        }
      }
      if (visual) sv.start.push_back(static_cast<int>(sv.row.size()));
    }
  }
  return kept;
}

std::string sci(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.0e", v);
  return buf;
}

// ---- 1. contact frames ---------------------------------------------------------------------------------------------

struct FrameResults {
  std::vector<Measure> measures;
  struct Dropped {
    double threshold = 0, kept_fraction = 0, dense_mib = 0, sparse_mib = 0;
    double disp = 0, force = 0, p50 = 0;
  };
  std::vector<Dropped> dropped;
};

FrameResults run_frames(const Organ& o, const Tensors& td, const Tensors& tf, const Settings& s) {
  FrameResults res;
  StaticSolver direct(*o.model);
  progress("frames: " + std::to_string(s.frames) + " per contact count, references by the direct solve");
  const std::vector<Frame> frames = make_frames(o, s, direct);
  const double kff_mib = static_cast<double>(sparse_bytes(o.model->k_ff)) / kMiB;
  double factor_mib = 0;
  {
    CholmodSolver probe;
    probe.analyze(o.model->k_ff);
    factor_mib = static_cast<double>(probe.factor_bytes()) / kMiB;
  }
  const auto solution_eval = [&](const StaticSolution& sol, Eigen::VectorXd& u, Eigen::Vector3d& force) {
    u = visible_part(o, sol.displacement);
    force = -sol.total_reaction;
  };

  progress("frames: full solve (factor + solve) per frame");
  Measure full{"full_solve", "factor_and_solve", kff_mib};
  measure(full, frames, s.solve_repeats, [&](const Frame& fr, Eigen::VectorXd& u, Eigen::Vector3d& f) {
    StaticSolver fresh(*o.model);
    solution_eval(fresh.solve(fr.imposed), u, f);
  });
  res.measures.push_back(std::move(full));

  progress("frames: prefactored direct solve");
  Measure pre{"prefactored", "direct", factor_mib};
  measure(pre, frames, s.solve_repeats, [&](const Frame& fr, Eigen::VectorXd& u, Eigen::Vector3d& f) {
    solution_eval(direct.solve(fr.imposed), u, f);
  });
  res.measures.push_back(std::move(pre));

  for (double tol : s.cg_tols) {
    progress("frames: CG at tolerance " + sci(tol));
    StaticSolverOptions opts;
    opts.method = SolveMethod::kCg;
    opts.cg_tolerance = tol;
    StaticSolver cg(*o.model, opts);
    Measure mc{"cg", "tol_" + sci(tol), kff_mib};
    measure(mc, frames, s.cg_repeats, [&](const Frame& fr, Eigen::VectorXd& u, Eigen::Vector3d& f) {
      const StaticSolution sol = cg.solve(fr.imposed);
      int& worst = mc.cg_iterations_max[fr.m];
      worst = std::max(worst, sol.iterations);
      solution_eval(sol, u, f);
    });
    res.measures.push_back(std::move(mc));
  }

  progress("frames: tensors (double, float)");
  for (const Tensors* t : {&td, &tf}) {
    TensorEvaluator eval(*t);
    Measure mt{t->precision == Precision::kDouble ? "tensors_double" : "tensors_float", "direct_precompute",
               static_cast<double>(t->bytes()) / kMiB};
    measure(mt, frames, s.tensor_repeats, [&](const Frame& fr, Eigen::VectorXd& u, Eigen::Vector3d& f) {
      if (!eval(fr.contacts.data(), fr.m, u, f)) throw Error("tensor evaluation failed");
    });
    res.measures.push_back(std::move(mt));
  }

  for (double thr : s.drop_thresholds) {
    progress("frames: far-field blocks dropped below " + sci(thr));
    Tensors t = td;  // a copy to zero blocks in
    SparseVisual sv;
    const std::size_t kept = drop_far_field(t, thr, sv);
    std::size_t total_blocks = 0;
    for (const auto& b : t.blocks) total_blocks += static_cast<std::size_t>(b.row_count()) * static_cast<std::size_t>(t.column_count());
    const double sparse_mib =
        (static_cast<double>(kept) * (9 * sizeof(double) + sizeof(int)) +
         static_cast<double>(t.blocks.size()) * (t.column_count() + 1) * sizeof(int)) / kMiB;
    Superposition haptic(t, "haptic");
    ContactSolution sol;
    Measure md{"tensors_dropped", "thr_" + sci(thr), sparse_mib};
    measure(md, frames, s.tensor_repeats, [&](const Frame& fr, Eigen::VectorXd& u, Eigen::Vector3d& f) {
      if (haptic.solve(fr.contacts.data(), fr.m, sol) != ContactStatus::kOk) throw Error("dropped tensors: G_CC solve failed");
      f = sol.tool_force;
      sv.displacements(sol.nodes.data(), sol.lambda.data(), sol.count, u);
    });
    FrameResults::Dropped d;
    d.threshold = thr;
    d.kept_fraction = static_cast<double>(kept) / static_cast<double>(total_blocks);
    d.dense_mib = static_cast<double>(td.bytes()) / kMiB;
    d.sparse_mib = sparse_mib;
    d.disp = md.worst(md.disp_error);
    d.force = md.worst(md.force_error);
    d.p50 = bench::percentile(md.all_times(), 0.5);
    res.dropped.push_back(d);
    res.measures.push_back(std::move(md));
  }
  return res;
}

// ---- 2. discretization -------------------------------------------------------------------------------------------

// Point location in a tet mesh: the containing tet (or the nearest by barycentric coordinates, clamped).
struct Locator {
  const TetMesh& mesh;
  std::vector<Eigen::Matrix3d> inv;  // #T: inverse of [x1-x0, x2-x0, x3-x0]
  explicit Locator(const TetMesh& m) : mesh(m), inv(static_cast<std::size_t>(m.tets.rows())) {
    for (Eigen::Index t = 0; t < m.tets.rows(); ++t) {
      Eigen::Matrix3d e;
      for (int a = 0; a < 3; ++a) e.col(a) = (m.nodes.row(m.tets(t, a + 1)) - m.nodes.row(m.tets(t, 0))).transpose();
      inv[static_cast<std::size_t>(t)] = e.inverse();
    }
  }
  // Interpolates the #V x 3 field at p; `outside` set when p is in no tet.
  Eigen::Vector3d interpolate(const Eigen::Vector3d& p, const Eigen::MatrixX3d& field, bool& outside) const {
    int best = 0;
    Eigen::Vector4d best_w = Eigen::Vector4d::Zero();
    double best_min = -std::numeric_limits<double>::infinity();
    for (Eigen::Index t = 0; t < mesh.tets.rows(); ++t) {
      const Eigen::Vector3d l = inv[static_cast<std::size_t>(t)] * (p - mesh.nodes.row(mesh.tets(t, 0)).transpose());
      const Eigen::Vector4d w(1 - l.sum(), l.x(), l.y(), l.z());
      const double mn = w.minCoeff();
      if (mn > best_min) {
        best_min = mn;
        best = static_cast<int>(t);
        best_w = w;
        if (mn >= 0) break;
      }
    }
    outside = best_min < -1e-9;
    best_w = best_w.cwiseMax(0.0);
    best_w /= best_w.sum();
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    for (int a = 0; a < 4; ++a) u += best_w[a] * field.row(mesh.tets(best, a)).transpose();
    return u;
  }
};

struct MeshRow {
  int nodes = 0, tets = 0, visible = 0, indenter = 0, outside = 0;
  Eigen::Vector3d force = Eigen::Vector3d::Zero();  // N, tool force
  double force_err = 0, disp_err = 0, factor_ms = 0, solve_ms = 0;
  double precompute_s = -1, tensor_mib = 0, p50 = -1, p99 = -1;
  bool precomputed = false;
  std::vector<Eigen::Vector3d> at_samples;
};

std::vector<MeshRow> run_meshes(const Scene& scene, const Settings& s) {
  std::vector<int> sizes = s.mesh_sizes;
  std::sort(sizes.begin(), sizes.end());
  std::vector<MeshRow> rows(sizes.size());
  std::vector<Eigen::Vector3d> samples;
  // Finest first: it defines the sample points.
  for (int i = static_cast<int>(sizes.size()) - 1; i >= 0; --i) {
    const int target = sizes[static_cast<std::size_t>(i)];
    progress("mesh: ~" + std::to_string(target) + " nodes: meshing (cache " + s.cache + ")");
    const auto o = make_organ(scene, target, s.cache, s.smoke);
    MeshRow& row = rows[static_cast<std::size_t>(i)];
    row.nodes = o->model->node_count();
    row.tets = static_cast<int>(o->mesh.tets.rows());
    row.visible = static_cast<int>(o->visible.size());
    const std::vector<int> punch = punch_nodes(*o);
    row.indenter = static_cast<int>(punch.size());
    if (punch.empty()) throw Error("mesh of " + std::to_string(row.nodes) + " nodes: no node under the punch");
    std::vector<ImposedDisplacement> imposed;
    std::vector<Contact> contacts;
    for (int k : punch) {
      imposed.push_back({k, Eigen::Vector3d(0, 0, -kMeshPunchDepth), 7});
      contacts.push_back({k, Eigen::Vector3d(0, 0, -kMeshPunchDepth)});
    }
    progress("mesh: " + std::to_string(row.nodes) + " nodes: direct solve");
    auto t0 = Clock::now();
    StaticSolver direct(*o->model);
    row.factor_ms = us_since(t0) * 1e-3;
    t0 = Clock::now();
    const StaticSolution sol = direct.solve(imposed);
    row.solve_ms = us_since(t0) * 1e-3;
    row.force = -sol.total_reaction;
    if (samples.empty()) {
      std::mt19937 rng(s.seed);
      std::vector<int> pool;
      for (int k : o->contacts)
        if (o->mesh.nodes(k, 2) > -0.02) pool.push_back(k);
      std::shuffle(pool.begin(), pool.end(), rng);
      pool.resize(std::min<std::size_t>(pool.size(), 300));
      // 3 mm under the surface, so that the coarser meshes' flat facets still contain most of them.
      for (int k : pool) samples.push_back((o->mesh.nodes.row(k) - kSampleDepth * o->normals.row(k)).transpose());
    }
    const Locator locator(o->mesh);
    for (const auto& p : samples) {
      bool outside = false;
      row.at_samples.push_back(locator.interpolate(p, sol.displacement, outside));
      row.outside += outside ? 1 : 0;
    }
    // Tensors: precomputed where affordable; otherwise the estimate of their memory.
    const auto opts = precompute_options(Precision::kDouble);
    if (row.nodes <= s.max_precompute_nodes && row.indenter <= kMaxContacts) {
      progress("mesh: " + std::to_string(row.nodes) + " nodes: precompute");
      PrecomputeReport rep;
      const Tensors t = precompute_tensors(*o->model, o->contacts, o->rows, opts, &rep);
      row.precompute_s = rep.total_s;
      row.tensor_mib = static_cast<double>(t.bytes()) / kMiB;
      TensorEvaluator eval(t);
      Eigen::VectorXd u;
      Eigen::Vector3d f = Eigen::Vector3d::Zero();
      std::vector<double> times;
      for (int r = 0; r < s.tensor_repeats * 4; ++r) {
        const auto tt = Clock::now();
        if (!eval(contacts.data(), static_cast<int>(contacts.size()), u, f)) throw Error("mesh: tensor evaluation failed");
        times.push_back(us_since(tt));
      }
      row.p50 = bench::percentile(times, 0.5);
      row.p99 = bench::percentile(times, 0.99);
      row.precomputed = true;
    } else {
      row.tensor_mib = static_cast<double>(
          estimate_precompute_memory(*o->model, static_cast<int>(o->contacts.size()), o->rows, opts).tensors) / kMiB;
    }
  }
  const MeshRow& finest = rows.back();
  double ref2 = 0;
  for (const auto& u : finest.at_samples) ref2 += u.squaredNorm();
  for (MeshRow& row : rows) {
    double e2 = 0;
    for (std::size_t i = 0; i < samples.size(); ++i) e2 += (row.at_samples[i] - finest.at_samples[i]).squaredNorm();
    row.disp_err = rel(std::sqrt(e2), std::sqrt(ref2));
    row.force_err = rel((row.force - finest.force).norm(), finest.force.norm());
  }
  return rows;
}

// ---- 3. non-linear -----------------------------------------------------------------------------------------------

struct NonlinearRow {
  double percent = 0, depth = 0;
  int indenter = 0;
  double newton_force = 0, linear_force = 0, quasi_force = 0;
  double linear_force_err = 0, quasi_force_err = 0, linear_disp_err = 0, quasi_disp_err = 0;
  bool converged = false;
  bool q_extrapolated = false;  // the linear force lies beyond the range Q was fitted on (its tangent is used)
  int steps = 0, iterations = 0;
  double newton_ms = 0, linear_p50 = 0, linear_p99 = 0, quasi_p50 = 0, quasi_p99 = 0;
};

std::vector<NonlinearRow> run_nonlinear(const Organ& o, const Tensors& td, const NonlinearLaw& law, const Settings& s) {
  std::vector<NonlinearRow> rows;
  const std::vector<int> punch = punch_nodes(o);
  if (punch.empty()) throw Error("non-linear: no node under the punch");
  if (static_cast<int>(punch.size()) > kMaxContacts) throw Error("non-linear: more punch nodes than kMaxContacts");
  TensorEvaluator eval(td);
  const TensorBlock& visual = eval.visual.block();
  for (double pct : s.indentations) {
    NonlinearRow row;
    row.percent = pct;
    row.depth = pct / 100 * o.height;
    row.indenter = static_cast<int>(punch.size());
    const Eigen::Vector3d d(0, 0, -row.depth);
    std::vector<ImposedDisplacement> imposed;
    std::vector<Contact> contacts;
    for (int k : punch) {
      imposed.push_back({k, d, 7});
      contacts.push_back({k, d});
    }
    HyperelasticOptions opts;
    opts.load_steps = std::max(2, static_cast<int>(std::ceil(row.depth / 0.002)));  // ~2 mm per increment
    progress("non-linear: " + std::to_string(static_cast<int>(pct)) + " % (" + std::to_string(row.depth * 1000).substr(0, 4) +
             " mm): Newton, " + std::to_string(opts.load_steps) + " increments");
    const HyperelasticSolver newton(*o.model, opts);
    const auto t0 = Clock::now();
    const HyperelasticSolution ref = newton.solve(imposed);
    row.newton_ms = us_since(t0) * 1e-3;
    row.converged = ref.converged();
    if (!row.converged) progress("non-linear: " + ref.message);
    for (const auto& st : ref.steps) row.steps += st.converged ? 1 : 0;
    row.iterations = ref.total_iterations;
    const Eigen::Vector3d f_ref = -ref.total_reaction;
    const Eigen::VectorXd u_ref = visible_part(o, ref.displacement);
    row.newton_force = f_ref.norm();

    // Linear, then the law as the nodes apply it, each timed as a frame.
    Eigen::VectorXd u_lin, u_quasi;
    Eigen::Vector3d f_lin = Eigen::Vector3d::Zero(), f_quasi = Eigen::Vector3d::Zero();
    std::vector<double> t_lin, t_quasi;
    for (int r = 0; r < s.tensor_repeats; ++r) {
      auto tt = Clock::now();
      if (!eval(contacts.data(), static_cast<int>(contacts.size()), u_lin, f_lin)) throw Error("non-linear: tensor evaluation failed");
      t_lin.push_back(us_since(tt));
      tt = Clock::now();
      eval(contacts.data(), static_cast<int>(contacts.size()), u_quasi, f_quasi);
      apply_quasi(law, eval.sol.displacement.data(), eval.sol.count, eval.sol.nodes.data(), visual, f_quasi, u_quasi);
      t_quasi.push_back(us_since(tt));
    }
    row.linear_force = f_lin.norm();
    row.q_extrapolated = law.force_fit() && std::abs(f_lin.dot(Eigen::Vector3d(0, 0, -1))) > law.force_fit()->map.t_max();
    row.quasi_force = f_quasi.norm();
    row.linear_force_err = rel((f_lin - f_ref).norm(), f_ref.norm());
    row.quasi_force_err = rel((f_quasi - f_ref).norm(), f_ref.norm());
    row.linear_disp_err = rel((u_lin - u_ref).norm(), u_ref.norm());
    row.quasi_disp_err = rel((u_quasi - u_ref).norm(), u_ref.norm());
    row.linear_p50 = bench::percentile(t_lin, 0.5);
    row.linear_p99 = bench::percentile(t_lin, 0.99);
    row.quasi_p50 = bench::percentile(t_quasi, 0.5);
    row.quasi_p99 = bench::percentile(t_quasi, 0.99);
    rows.push_back(row);
  }
  return rows;
}

// Empty cell for "not measured" (negative), else the number.
std::string cell(double v, const char* format = "%.6g") {
  if (v < 0) return "";
  char buf[48];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

}  // namespace

int main(int argc, char** argv) {
  Settings s;
  bool quick = false;
  CLI::App app{
      "liver_error_bench: the liver's error against run time: per-frame solves, CG tolerances, "
      "precomputed tensors (double, float, far field dropped), mesh size, and linear / quasi non-linear "
      "against a neo-Hookean Newton reference. Tables on stdout, progress on stderr, CSV files with --out."};
  app.add_option("--out", s.out, "Write the CSV files to this folder (created if missing)");
  app.add_option("--cache", s.cache, "Mesh cache folder (default: $SURGSIM_CACHE_DIR, else ~/.cache/surgsim)");
  app.add_option("--scene", s.scene, "Scene (name or YAML) giving the material, clamp and curves")->capture_default_str();
  app.add_option("--nodes", s.nodes, "Target node count of the main liver")->capture_default_str();
  app.add_option("--mesh-sizes", s.mesh_sizes, "Target node counts of the discretization study")->delimiter(',')->capture_default_str();
  app.add_option("--max-precompute-nodes", s.max_precompute_nodes, "Precompute tensors in the mesh study up to this many nodes")->capture_default_str();
  app.add_option("--frames", s.frames, "Contact frames per contact count (1, 3, 10 contacts)")->capture_default_str();
  app.add_option("--repeats", s.tensor_repeats, "Repeats per frame of a tensor evaluation")->capture_default_str();
  app.add_option("--solve-repeats", s.solve_repeats, "Repeats per frame of a direct solve")->capture_default_str();
  app.add_option("--cg-tols", s.cg_tols, "CG relative residual tolerances")->delimiter(',')->capture_default_str();
  app.add_option("--drop-thresholds", s.drop_thresholds, "Far-field block thresholds, relative to the column's diagonal block")->delimiter(',')->capture_default_str();
  app.add_option("--indentations", s.indentations, "Punch depths, % of the organ's height")->delimiter(',')->capture_default_str();
  app.add_option("--seed", s.seed, "Seed of the contact frames")->capture_default_str();
  app.add_flag("--quick", quick, "Short run: 4 frames per count, no 20k mesh, fewer repeats (under ~1.5 min)");
  app.add_flag("--smoke", s.smoke, "Tiny run on box meshes (no Gmsh; a few seconds): the ctest's configuration");
  CLI11_PARSE(app, argc, argv);
  if (quick) {
    s.frames = std::min(s.frames, 4);
    s.tensor_repeats = std::min(s.tensor_repeats, 40);
    s.solve_repeats = std::min(s.solve_repeats, 2);
    s.mesh_sizes.erase(std::remove_if(s.mesh_sizes.begin(), s.mesh_sizes.end(), [](int n) { return n > 8000; }),
                       s.mesh_sizes.end());
  }
  if (s.smoke) {
    s.nodes = 300;
    s.mesh_sizes = {150, 300, 700};
    s.frames = 2;
    s.tensor_repeats = 5;
    s.solve_repeats = 1;
    s.drop_thresholds = {1e-3, 1e-1};
    s.indentations = {10, 30};
  }
  if (s.mesh_sizes.empty() || s.frames < 1 || s.tensor_repeats < 1 || s.solve_repeats < 1) {
    std::cerr << "liver_error_bench: --mesh-sizes, --frames and the repeats must not be empty or zero\n";
    return 2;
  }

  try {
    const auto start = Clock::now();
    const Scene scene = load_scene(resolve_scene_path(s.scene));
    if (s.cache.empty() && !s.smoke) s.cache = default_cache_dir();
    if (!s.out.empty()) bench::make_dirs(s.out);
    const NonlinearLaw law = load_nonlinear_law(scene.nonlinear, scene.material);

    progress("main organ: ~" + std::to_string(s.nodes) + " nodes");
    const auto organ = make_organ(scene, s.nodes, s.cache, s.smoke);
    progress("main organ: " + std::to_string(organ->model->node_count()) + " nodes; precompute (double, float)");
    PrecomputeReport rep_d, rep_f;
    const Tensors td = precompute_tensors(*organ->model, organ->contacts, organ->rows, precompute_options(Precision::kDouble), &rep_d);
    const Tensors tf = precompute_tensors(*organ->model, organ->contacts, organ->rows, precompute_options(Precision::kFloat), &rep_f);

    std::printf("Liver error against run time: %s of %d nodes, %d tets, %d contactable, %d visible; E %.0f Pa, nu %.2f; "
                "tensors %.2f s (double, %.1f MiB), %.2f s (float, %.1f MiB)\n",
                organ->kind.c_str(), organ->model->node_count(), static_cast<int>(organ->mesh.tets.rows()),
                static_cast<int>(organ->contacts.size()), static_cast<int>(organ->visible.size()),
                scene.material.young_modulus, scene.material.poisson_ratio, rep_d.total_s, td.bytes() / kMiB,
                rep_f.total_s, tf.bytes() / kMiB);

    std::vector<SummaryRow> summary;
    // 1. Contact frames.
    const FrameResults fr = run_frames(*organ, td, tf, s);
    CsvOut frames_csv(s.out, "liver_error_frames",
                      "family,variant,contacts,frames,time_per_frame_us_p50,time_per_frame_us_p99,disp_rel_error_max,"
                      "disp_rel_error_median,force_rel_error_max,cg_iterations_max");
    std::printf("\n1. Contact frames (%d per contact count; errors against the direct solve in double: worst frame)\n",
                s.frames);
    std::printf("%-16s %-18s %8s | %12s %12s | %10s %10s | %9s\n", "family", "variant", "contacts", "p50 us", "p99 us",
                "disp err", "force err", "CG iters");
    for (const Measure& m : fr.measures) {
      for (const auto& [count, times] : m.time_us) {
        const auto& de = m.disp_error.at(count);
        const auto& fe = m.force_error.at(count);
        const auto it = m.cg_iterations_max.find(count);
        const int iters = it == m.cg_iterations_max.end() ? 0 : it->second;
        const double dmax = *std::max_element(de.begin(), de.end()), fmax = *std::max_element(fe.begin(), fe.end());
        std::printf("%-16s %-18s %8d | %12.2f %12.2f | %10.2e %10.2e | %9d\n", m.family.c_str(), m.variant.c_str(),
                    count, bench::percentile(times, 0.5), bench::percentile(times, 0.99), dmax, fmax, iters);
        frames_csv.row("%s,%s,%d,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%d", m.family.c_str(), m.variant.c_str(), count,
                       static_cast<int>(de.size()), bench::percentile(times, 0.5), bench::percentile(times, 0.99), dmax,
                       bench::percentile(de, 0.5), fmax, iters);
      }
      const auto all = m.all_times();
      summary.push_back({m.family, m.variant, bench::percentile(all, 0.5), bench::percentile(all, 0.99),
                         m.worst(m.disp_error), m.worst(m.force_error), m.memory_mib});
    }
    CsvOut dropped_csv(s.out, "liver_error_dropped",
                       "threshold_rel,blocks_kept_fraction,memory_dense_mib,memory_sparse_mib,saved_fraction,saved_mib,"
                       "disp_rel_error,force_rel_error,time_per_frame_us_p50");
    std::printf("\nFar-field blocks dropped (|G(r,c)| < t |G(c,c)|; memory as 3x3 block-sparse storage, both blocks)\n");
    std::printf("%10s %10s %10s %10s %8s %10s | %10s %10s | %10s\n", "threshold", "kept", "dense MiB", "sparse MiB",
                "saved", "saved MiB", "disp err", "force err", "p50 us");
    for (const auto& d : fr.dropped) {
      const double saved = 1 - d.sparse_mib / d.dense_mib;
      std::printf("%10.0e %9.1f%% %10.2f %10.2f %7.1f%% %10.2f | %10.2e %10.2e | %10.2f\n", d.threshold,
                  100 * d.kept_fraction, d.dense_mib, d.sparse_mib, 100 * saved, d.dense_mib - d.sparse_mib, d.disp,
                  d.force, d.p50);
      dropped_csv.row("%.3g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g", d.threshold, d.kept_fraction, d.dense_mib,
                      d.sparse_mib, saved, d.dense_mib - d.sparse_mib, d.disp, d.force, d.p50);
    }

    // 2. Discretization.
    const std::vector<MeshRow> meshes = run_meshes(scene, s);
    CsvOut mesh_csv(s.out, "liver_mesh_convergence",
                    "nodes,tets,visible_nodes,indenter_nodes,force_n,force_rel_error,disp_rel_error,samples_outside,"
                    "factor_ms,solve_ms,precompute_s,tensor_mib,tensor_frame_us_p50,tensor_frame_us_p99");
    std::printf("\n2. Discretization: punch of %.0f mm (radius %.0f mm) against the finest mesh (%d nodes); disp at %d "
                "sample points\n",
                kMeshPunchDepth * 1000, kPunchRadius * 1000, meshes.back().nodes,
                static_cast<int>(meshes.back().at_samples.size()));
    std::printf("%7s %7s %6s | %9s %10s %10s %7s | %9s %9s %11s %10s %12s %12s\n", "nodes", "tets", "punch", "force N",
                "force err", "disp err", "outside", "factor ms", "solve ms", "precomp s", "tens MiB", "tensor p50us",
                "tensor p99us");
    for (const MeshRow& r : meshes) {
      std::printf("%7d %7d %6d | %9.4f %10.2e %10.2e %7d | %9.1f %9.2f %11s %10.1f %12s %12s\n", r.nodes, r.tets,
                  r.indenter, r.force.norm(), r.force_err, r.disp_err, r.outside, r.factor_ms, r.solve_ms,
                  r.precomputed ? cell(r.precompute_s, "%.2f").c_str() : "-", r.tensor_mib,
                  r.precomputed ? cell(r.p50, "%.2f").c_str() : "-", r.precomputed ? cell(r.p99, "%.2f").c_str() : "-");
      mesh_csv.row("%d,%d,%d,%d,%.6g,%.6g,%.6g,%d,%.6g,%.6g,%s,%.6g,%s,%s", r.nodes, r.tets, r.visible, r.indenter,
                   r.force.norm(), r.force_err, r.disp_err, r.outside, r.factor_ms, r.solve_ms,
                   cell(r.precompute_s).c_str(), r.tensor_mib, cell(r.p50).c_str(), cell(r.p99).c_str());
      summary.push_back({"mesh", "nodes_" + std::to_string(r.nodes) + (r.precomputed ? "_tensors" : "_solve"),
                         r.precomputed ? r.p50 : r.solve_ms * 1000, r.precomputed ? r.p99 : r.solve_ms * 1000,
                         r.disp_err, r.force_err, r.tensor_mib});
    }
    std::printf("(tens MiB: estimated when not precomputed; the time per frame of those is the prefactored solve.)\n");

    // 3. Non-linear.
    const std::vector<NonlinearRow> nl = run_nonlinear(*organ, td, law, s);
    CsvOut nl_csv(s.out, "liver_nonlinear",
                  "indentation_percent,indentation_mm,indenter_nodes,newton_force_n,linear_force_n,quasi_force_n,"
                  "linear_force_rel_error,quasi_force_rel_error,linear_disp_rel_error,quasi_disp_rel_error,"
                  "newton_converged,newton_load_steps,newton_iterations,newton_ms,linear_frame_us_p50,quasi_frame_us_p50,"
                  "q_extrapolated");
    std::printf("\n3. Non-linear: punch of %d nodes at %% of the organ's height (%.1f mm), against neo-Hookean Newton\n",
                nl.empty() ? 0 : nl[0].indenter, organ->height * 1000);
    std::printf("%5s %7s | %9s %9s %9s | %10s %10s %10s %10s | %4s %5s %6s %9s | %9s %9s %9s\n", "%", "mm", "Newton N",
                "linear N", "quasi N", "lin F err", "qnl F err", "lin u err", "qnl u err", "conv", "steps", "iters",
                "Newton ms", "lin us", "qnl us", "Q extrap");
    for (const NonlinearRow& r : nl) {
      std::printf("%5.0f %7.2f | %9.4f %9.4f %9.4f | %10.2e %10.2e %10.2e %10.2e | %4s %5d %6d %9.1f | %9.2f %9.2f %9s\n",
                  r.percent, r.depth * 1000, r.newton_force, r.linear_force, r.quasi_force, r.linear_force_err,
                  r.quasi_force_err, r.linear_disp_err, r.quasi_disp_err, r.converged ? "yes" : "NO", r.steps,
                  r.iterations, r.newton_ms, r.linear_p50, r.quasi_p50, r.q_extrapolated ? "yes" : "no");
      nl_csv.row("%.6g,%.6g,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%d,%d,%d,%.6g,%.6g,%.6g,%d", r.percent,
                 r.depth * 1000, r.indenter, r.newton_force, r.linear_force, r.quasi_force, r.linear_force_err,
                 r.quasi_force_err, r.linear_disp_err, r.quasi_disp_err, r.converged ? 1 : 0, r.steps, r.iterations,
                 r.newton_ms, r.linear_p50, r.quasi_p50, r.q_extrapolated ? 1 : 0);
      const std::string p = std::to_string(static_cast<int>(std::lround(r.percent))) + "pct";
      const double mib = td.bytes() / kMiB;
      summary.push_back({"linear_vs_nonlinear", "linear_" + p, r.linear_p50, r.linear_p99, r.linear_disp_err,
                         r.linear_force_err, mib});
      summary.push_back({"linear_vs_nonlinear", "quasi_" + p, r.quasi_p50, r.quasi_p99, r.quasi_disp_err,
                         r.quasi_force_err, mib});
      summary.push_back({"linear_vs_nonlinear", "newton_" + p, r.newton_ms * 1000, r.newton_ms * 1000, 0, 0,
                         static_cast<double>(sparse_bytes(organ->model->k)) / kMiB});
    }

    // Summary.
    CsvOut time_csv(s.out, "liver_error_time",
                    "family,variant,time_per_frame_us_p50,time_per_frame_us_p99,disp_rel_error,force_rel_error,memory_mib");
    std::printf("\nSummary (liver_error_time.csv): error against time per frame\n");
    std::printf("%-20s %-22s | %13s %13s | %10s %10s | %10s\n", "family", "variant", "p50 us", "p99 us", "disp err",
                "force err", "memory MiB");
    for (const SummaryRow& r : summary) {
      std::printf("%-20s %-22s | %13.2f %13.2f | %10.2e %10.2e | %10.2f\n", r.family.c_str(), r.variant.c_str(), r.p50,
                  r.p99, r.disp, r.force, r.memory_mib);
      time_csv.row("%s,%s,%.6g,%.6g,%.6g,%.6g,%.6g", r.family.c_str(), r.variant.c_str(), r.p50, r.p99, r.disp, r.force,
                   r.memory_mib);
    }
    std::printf("\nTotal %.1f s\n", us_since(start) * 1e-6);
    if (!s.out.empty()) progress("CSV files in " + s.out);
  } catch (const std::exception& e) {
    std::cerr << "liver_error_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
