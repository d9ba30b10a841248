// liver_bench: precompute time and memory for organs of ~500 to 21k nodes (direct CHOLMOD against CG per column),
// and the paper's Table 1: time to evaluate 1, 5, 10, 20 contacts with the tensors against the reference solve of the
// same load. Prints tables; run by hand (not a ctest). Each precomputation runs in a forked child so that its peak
// resident memory (getrusage ru_maxrss) is its own. The direct precompute stores what the scenes store (the haptic
// block as one packed half, the visual rows without fully fixed nodes, float above 1 GiB of double) on every core;
// the budgets (docs/DESIGN.md, section 'Budgets'): <= 0.5 s at 1.4k nodes, <= 5 s at 5k, <= 60 s and <= 2 GB at 21k:
//   build/bench/liver_bench --sizes 1500,5000,20000 --no-cg --skip-table
#include <CLI/CLI.hpp>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "mesh/box_mesh.h"
#include "csv_out.h"
#include "fork_child.h"
#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "liver/liver_setup.h"
#include "compliance/precompute.h"
#include "fem/static_solver.h"
#include "compliance/superposition.h"
#include "mesher/organ_mesher.h"

using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::liver;
using namespace surgsim::mesher;

namespace {

using namespace surgsim;
using Clock = std::chrono::steady_clock;

double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

double rss_now_mib() {
  long pages = 0, resident = 0;
  if (std::FILE* f = std::fopen("/proc/self/statm", "r")) {
    if (std::fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = 0;
    std::fclose(f);
  }
  return static_cast<double>(resident) * static_cast<double>(sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
}

// An organ: mesh, material, fixed set (underside z <= -0.025 m, as in config/liver.yaml), model.
struct Organ {
  std::string kind;
  TetMesh mesh;
  Material material;
  FixedSet fixed;
  std::unique_ptr<ElasticModel> model;
  std::vector<int> contacts;
  std::vector<RowSet> rows;
};

std::unique_ptr<Organ> make_organ(int target_nodes, bool box) {
  auto o = std::make_unique<Organ>();
  if (!box) {
    o->kind = "liver";
    o->mesh = generate_organ(OrganSpec{"liver", target_nodes});
  }
  if (o->mesh.nodes.rows() == 0) {
    o->kind = "box";
    o->mesh = make_box_mesh_with_nodes(target_nodes, Eigen::Vector3d(0.26, 0.16, 0.08));
    o->mesh.nodes.rowwise() -= Eigen::RowVector3d(0.13, 0.08, 0.04);
  }
  o->material.young_modulus = 3000;
  o->material.poisson_ratio = 0.45;
  FixedRegion r;
  r.has_plane = true;
  r.plane_point = Eigen::Vector3d(0, 0, -0.025);
  r.plane_normal = -Eigen::Vector3d::UnitZ();
  o->fixed = fixed_set_from_region(o->mesh, r);
  o->model = std::make_unique<ElasticModel>(build_elastic_model(o->mesh, o->material, o->fixed));
  o->contacts = contactable_nodes(o->mesh, o->fixed);
  o->rows = standard_row_sets(o->mesh, o->fixed, o->contacts);
  return o;
}

// What a forked precomputation sends back.
struct ChildResult {
  int ok = 0;
  double seconds = 0;          // measured
  double extrapolated = 0;     // seconds for all columns (= seconds when all columns were solved)
  int columns_solved = 0;
  double rss_start_mib = 0, rss_peak_mib = 0, estimate_mib = 0, tensor_mib = 0;
  int cg_iterations = 0;
  double cg_error = 0;         // max |G_cg - G_direct| / max |G_direct| over the solved columns
  int threads = 0;             // direct: solving threads
  int float_storage = 0;       // direct: 1 when stored in float
  char error[200] = {0};
};

void run_direct(const Organ& o, int block, int threads, ChildResult& r) {
  r.rss_start_mib = rss_now_mib();
  PrecomputeOptions opts = scene_precompute_options(static_cast<int>(o.contacts.size()), o.rows);
  opts.block_columns = block;
  opts.threads = threads;
  opts.memory_limit_mb = 0;
  r.float_storage = opts.precision == Precision::kFloat ? 1 : 0;
  r.estimate_mib = static_cast<double>(
      estimate_precompute_memory(*o.model, static_cast<int>(o.contacts.size()), o.rows, opts).total()) / (1 << 20);
  PrecomputeReport rep;
  const Tensors t = precompute_tensors(*o.model, o.contacts, o.rows, opts, &rep);
  r.seconds = r.extrapolated = rep.total_s;
  r.columns_solved = 3 * t.column_count();
  r.tensor_mib = static_cast<double>(t.bytes()) / (1 << 20);
  r.rss_peak_mib = bench::maxrss_mib();
  r.threads = rep.threads;
}

// CG per column over an evenly spaced subset of the contact nodes (all when `max_columns` allows), extrapolated.
void run_cg(const Organ& o, double tol, int max_columns, ChildResult& r) {
  r.rss_start_mib = rss_now_mib();
  const int s = static_cast<int>(o.contacts.size());
  const int take = std::max(1, std::min(s, max_columns / 3));
  std::vector<int> subset;
  for (int i = 0; i < take; ++i) subset.push_back(o.contacts[static_cast<std::size_t>(static_cast<long>(i) * s / take)]);
  PrecomputeOptions opts;
  opts.method = SolveMethod::kCg;
  opts.cg_tolerance = tol;
  opts.memory_limit_mb = 0;
  // Memory: the full run's estimate (the subset run stores fewer columns).
  r.estimate_mib = static_cast<double>(estimate_precompute_memory(*o.model, s, o.rows, opts).total()) / (1 << 20);
  PrecomputeReport rep;
  const Tensors t = precompute_tensors(*o.model, subset, o.rows, opts, &rep);
  r.seconds = rep.total_s;
  r.columns_solved = 3 * take;
  r.extrapolated = rep.total_s * static_cast<double>(s) / take;
  r.cg_iterations = rep.cg_max_iterations;
  r.rss_peak_mib = bench::maxrss_mib();
  r.tensor_mib = static_cast<double>(t.bytes()) / (1 << 20) * s / take;
  // Error against the direct solution of the same columns.
  const Tensors d = precompute_tensors(*o.model, subset, o.rows, PrecomputeOptions());
  const auto& gc = t.find("visual")->g;
  const auto& gd = d.find("visual")->g;
  r.cg_error = (gc - gd).cwiseAbs().maxCoeff() / gd.cwiseAbs().maxCoeff();
}

template <typename F>
double median_us(int repeats, F&& f) {
  std::vector<double> t;
  for (int i = 0; i < repeats; ++i) {
    const auto t0 = Clock::now();
    f();
    t.push_back(since(t0) * 1e6);
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

// Contacts around a random surface node: its m nearest contactable nodes (a tool-sized patch), pushed down 5 mm.
std::vector<Contact> contact_patch(const Organ& o, int m, std::mt19937& rng) {
  std::uniform_int_distribution<std::size_t> pick(0, o.contacts.size() - 1);
  const Eigen::Vector3d c = o.mesh.nodes.row(o.contacts[pick(rng)]).transpose();
  std::vector<std::pair<double, int>> by_distance;
  for (int k : o.contacts) by_distance.emplace_back((o.mesh.nodes.row(k).transpose() - c).norm(), k);
  std::partial_sort(by_distance.begin(), by_distance.begin() + m, by_distance.end());
  std::vector<Contact> out;
  for (int i = 0; i < m; ++i)
    out.push_back({by_distance[static_cast<std::size_t>(i)].second, Eigen::Vector3d(0.0005 * (i % 3), 0, -0.005)});
  return out;
}

void table1(const Organ& o, int repeats, double cg_tol, bench::CsvOut& csv) {
  PrecomputeOptions opts;
  opts.memory_limit_mb = 0;
  const auto tp = Clock::now();
  const Tensors t = precompute_tensors(*o.model, o.contacts, o.rows, opts);
  const double precompute_s = since(tp);
  Superposition haptic(t, "haptic", kMaxContacts);
  const Superposition visual(t, "visual");
  StaticSolver direct(*o.model);
  StaticSolverOptions cg_opts;
  cg_opts.method = SolveMethod::kCg;
  cg_opts.cg_tolerance = cg_tol;
  StaticSolver cg(*o.model, cg_opts);
  Eigen::VectorXd u(3 * visual.block().row_count());
  std::mt19937 rng(42);

  std::printf("\nTable 1 (paper): time per evaluation, %s of %d nodes, %d contactable, %d visible; tensors precomputed "
              "in %.2f s (direct, double)\n",
              o.kind.c_str(), o.model->node_count(), static_cast<int>(o.contacts.size()), visual.block().row_count(),
              precompute_s);
  std::printf("%8s | %12s %12s %12s | %12s %14s %12s | %10s\n", "contacts", "haptic us", "visual us", "tensor us",
              "ref direct ms", "ref+factor ms", "ref CG ms", "rel error");
  std::printf("%8s | %12s %12s %12s | %12s %14s %12s | %10s\n", "", "(lambda,F,", "(all visible", "(total)",
              "(K_ff factored)", "(from scratch)", "", "vs direct");
  for (int m : {1, 5, 10, 20}) {
    const std::vector<Contact> contacts = contact_patch(o, m, rng);
    std::vector<ImposedDisplacement> imposed;
    for (const auto& c : contacts) imposed.push_back({c.node, c.displacement, 7});
    ContactSolution sol;
    Eigen::Vector3d near[10];
    // Haptic: lambda, force, and the displacement of 10 candidate nodes (those the collision test would look at).
    const double haptic_us = median_us(repeats, [&] {
      haptic.solve(contacts.data(), m, sol);
      for (int i = 0; i < 10; ++i) haptic.displacement(o.contacts[static_cast<std::size_t>(i * 7)], sol, near[i]);
    });
    const double visual_us = median_us(repeats, [&] { visual.displacements(sol.nodes.data(), sol.lambda.data(), sol.count, u); });
    const int ref_repeats = std::max(3, std::min(repeats, 15));
    StaticSolution ref;
    const double direct_ms = median_us(ref_repeats, [&] { ref = direct.solve(imposed); }) / 1000;
    const double scratch_ms = median_us(3, [&] {
                                StaticSolver fresh(*o.model);
                                fresh.solve(imposed);
                              }) / 1000;
    const double cg_ms = median_us(3, [&] { cg.solve(imposed); }) / 1000;
    // Agreement on the visible nodes.
    double err = 0, scale = 0;
    for (int r = 0; r < visual.block().row_count(); ++r) {
      const int n = visual.block().row_nodes[static_cast<std::size_t>(r)];
      err = std::max(err, (u.segment<3>(3 * r) - ref.displacement.row(n).transpose()).cwiseAbs().maxCoeff());
      scale = std::max(scale, ref.displacement.row(n).cwiseAbs().maxCoeff());
    }
    std::printf("%8d | %12.2f %12.2f %12.2f | %12.3f %14.3f %12.3f | %10.2e\n", m, haptic_us, visual_us,
                haptic_us + visual_us, direct_ms, scratch_ms, cg_ms, err / scale);
    csv.row("%d,%d,%.3f,%.3f,%.3f,%.4f,%.4f,%.4f,%.3e", o.model->node_count(), m, haptic_us, visual_us,
            haptic_us + visual_us, direct_ms, scratch_ms, cg_ms, err / scale);
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> sizes = {500, 1500, 5000};
  bool large = false, box = false, skip_table = false, no_cg = false;
  std::string out;
  int cg_columns = 300, repeats = 2000, block = PrecomputeOptions().block_columns, table_nodes = 1500, threads = 0;
  double cg_tol = 1e-8;
  CLI::App app{"liver_bench: precompute time and peak memory (direct vs CG) and the paper's Table 1 (tensor evaluation "
               "vs reference solve)."};
  app.add_option("--sizes", sizes, "Target node counts")->delimiter(',')->capture_default_str();
  app.add_flag("--large", large, "Add the 20k-target organ (about 21k nodes; ~30 s and ~1.7 GB direct, CG much longer)");
  app.add_flag("--no-cg", no_cg, "Skip the CG columns (direct only)");
  app.add_option("--threads", threads, "Direct: solving threads (0: every core)")->capture_default_str();
  app.add_flag("--box", box, "Use structured boxes even when the liver mesher is built");
  app.add_option("--cg-columns", cg_columns, "CG: solve at most this many columns, extrapolate to all")->capture_default_str();
  app.add_option("--cg-tol", cg_tol, "CG relative residual (precompute columns and reference solve)")->capture_default_str();
  app.add_option("--block", block, "Direct: right-hand sides per CHOLMOD solve")->capture_default_str();
  app.add_option("--repeats", repeats, "Repeats per tensor timing (median)")->capture_default_str();
  app.add_option("--table-nodes", table_nodes, "Organ size for Table 1 (the closest of --sizes)")->capture_default_str();
  app.add_flag("--skip-table", skip_table, "Only the precompute table");
  app.add_option("--out", out, "Also write liver_precompute.csv and liver_table1.csv into this existing folder");
  CLI11_PARSE(app, argc, argv);
  if (large) sizes.push_back(20000);
  if (no_cg) cg_columns = 0;

  try {
    bench::CsvOut pre_csv(out, "liver_precompute",
                          "organ,nodes,tets,contactable,columns,direct_s,direct_peak_mib,estimate_mib,cg_s,cg_extrapolated,"
                          "cg_columns_solved,cg_iterations_max,cg_rel_error,tensor_mib,threads,precision");
    bench::CsvOut table_csv(out, "liver_table1",
                            "nodes,contacts,haptic_us,visual_us,tensor_total_us,ref_direct_ms,ref_factor_and_solve_ms,"
                            "ref_cg_ms,rel_error");
    std::printf("Precompute (G = K_ff^-1 on 3S contactable columns; rows: haptic = contactable, one packed half; visual "
                "= boundary nodes that can move; direct as the scenes store it: double, or float above 1 GiB of "
                "double, marked f). CG tol %.0e, Jacobi preconditioner, double, columns sampled and extrapolated when "
                "more than %d.\n",
                cg_tol, cg_columns);
    std::printf("%-6s %7s %7s %6s %7s | %9s %9s %9s %9s | %10s %6s %9s %6s %9s %9s %4s\n", "organ", "nodes", "tets", "S",
                "cols", "direct s", "peak MiB", "+MiB", "est MiB", "CG s", "cols", "CG peak", "iters", "CG err",
                "tens MiB", "thr");
    std::unique_ptr<Organ> table_organ;
    for (int n : sizes) {
      auto o = make_organ(n, box);
      const ChildResult d = bench::in_child<ChildResult>([&](ChildResult& r) { run_direct(*o, block, threads, r); });
      ChildResult c;
      if (no_cg) {
        c.ok = 1;
      } else {
        c = bench::in_child<ChildResult>([&](ChildResult& r) { run_cg(*o, cg_tol, cg_columns, r); });
      }
      if (!d.ok || !c.ok) {
        std::printf("%-6s %7d: failed: %s %s\n", o->kind.c_str(), o->model->node_count(), d.error, c.error);
        continue;
      }
      char cg_s[32];
      std::snprintf(cg_s, sizeof cg_s, c.columns_solved < 3 * static_cast<int>(o->contacts.size()) ? "%.1f est" : "%.2f",
                    c.extrapolated);
      std::printf("%-6s %7d %7d %6d %7d | %9.3f %9.1f %9.1f %9.1f | %10s %6d %9.1f %6d %9.1e %8.1f%s %4d\n", o->kind.c_str(),
                  o->model->node_count(), static_cast<int>(o->mesh.tets.rows()), static_cast<int>(o->contacts.size()),
                  3 * static_cast<int>(o->contacts.size()), d.seconds, d.rss_peak_mib, d.rss_peak_mib - d.rss_start_mib,
                  d.estimate_mib, no_cg ? "-" : cg_s, c.columns_solved, c.rss_peak_mib, c.cg_iterations, c.cg_error,
                  d.tensor_mib, d.float_storage ? "f" : " ", d.threads);
      pre_csv.row("%s,%d,%d,%d,%d,%.4f,%.1f,%.1f,%.3f,%d,%d,%d,%.3e,%.2f,%d,%s", o->kind.c_str(), o->model->node_count(),
                  static_cast<int>(o->mesh.tets.rows()), static_cast<int>(o->contacts.size()),
                  3 * static_cast<int>(o->contacts.size()), d.seconds, d.rss_peak_mib, d.estimate_mib, c.extrapolated,
                  c.columns_solved < 3 * static_cast<int>(o->contacts.size()) ? 1 : 0, c.columns_solved, c.cg_iterations,
                  c.cg_error, d.tensor_mib, d.threads, d.float_storage ? "float" : "double");
      std::fflush(stdout);
      if (!table_organ || std::abs(n - table_nodes) < std::abs(static_cast<int>(table_organ->model->node_count()) - table_nodes))
        table_organ = std::move(o);
    }
    std::printf("(peak MiB: the child's ru_maxrss, including the mesh and model inherited at fork; +MiB: above its "
                "resident size at start; est MiB: estimate_precompute_memory.)\n");
    if (table_organ && !skip_table) table1(*table_organ, repeats, cg_tol, table_csv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "liver_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
