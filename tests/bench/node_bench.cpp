// node_bench: the run-phase costs of both nodes on generated livers, measured side by side in one run.
//   haptic tick (collision on the deformed surface + G_CC solve + force) against contact count and mesh size;
//   visual deformation of every visible node against mesh size; render time at 640x480 (and 1280x720 at the first
//   size); the peak memory of each node.
// A plain program printing tables (run by hand, never a pass/fail test):
//   build/bench/node_bench [--sizes 1500,5000,20000] [--reps 2000] [--no-render] [--out DIR]
// --out DIR also writes node_tick.csv, node_deform.csv, node_render.csv and node_memory.csv there.
// Tensors come from the shared cache ($SURGSIM_CACHE_DIR), built on first use in a child process whose time and
// peak resident memory are the "first use" row; then the haptic side (the "haptic" block only, as the haptic node
// loads it) and the visual side (the "visual" block only) each run in their own child, so that each peak resident
// memory (getrusage ru_maxrss) is that node's working set of tensors, mesh and grid.
#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <random>

#include "core/clock.h"
#include "csv_out.h"
#include "fork_child.h"
#include "contact/bucket_grid.h"
#include "contact/tool_contacts.h"
#include "liver/liver_setup.h"
#include "mesher/organ_mesher.h"
#include "render/renderer.h"
#include "scene/scene.h"
#include "mesher/scene_mesh.h"
#include "core/stats.h"
#include "views/surface_deformer.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::tool;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::contact;
using namespace surgsim::liver;
using namespace surgsim::intestine;
using namespace surgsim::scene;
using namespace surgsim::mesher;

using namespace surgsim;

namespace {

// What a child sends back.
struct ChildResult {
  int ok = 0;
  double seconds = 0, peak_mib = 0, tensor_mib = 0;
  int rebuilt = 0;
  char error[240] = {0};
};

// A child that also records its peak resident memory.
template <typename F>
ChildResult in_child(F&& work) {
  return bench::in_child<ChildResult>([&](ChildResult& r) {
    work(r);
    r.peak_mib = bench::maxrss_mib();
  });
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> sizes = {1500, 5000};
  int reps = 2000;
  bool render = true;
  std::string out;
  CLI::App cli{"surgsim node benchmarks: haptic tick against contacts and mesh size, visual deformation and render "
               "times (percentiles, side by side in one run), and each node's peak memory."};
  cli.add_option("--sizes", sizes, "Liver node counts (generated; 20000 gives the ~21k-node liver)")
      ->delimiter(',')->capture_default_str();
  cli.add_option("--reps", reps, "Repetitions per measurement")->capture_default_str();
  cli.add_flag("!--no-render", render, "Skip the OSMesa render timings");
  cli.add_option("--out", out, "Also write the tables as CSV files into this existing folder");
  CLI11_PARSE(cli, argc, argv);
  try {
  // Headers only: the children append their rows.
  { bench::CsvOut(out, "node_tick", "nodes,surface_nodes,contacts,tick_us_p50,tick_us_p90,tick_us_p99,tick_us_max"); }
  { bench::CsvOut(out, "node_deform", "visible_nodes,contacts,deform_us_p50,deform_us_p99,deform_us_max,nodes"); }
  { bench::CsvOut(out, "node_render", "width,height,visible_nodes,frame_ms_p50,frame_ms_p99,frame_ms_max"); }
  bench::CsvOut memory_csv(out, "node_memory",
                           "nodes,contactable,first_use_s,first_use_rebuilt,first_use_peak_mib,haptic_peak_mib,"
                           "haptic_tensor_mib,visual_peak_mib,visual_tensor_mib,precision");

  const Scene base = load_scene(resolve_scene_path("liver"));
  const std::string cache = default_cache_dir();
  std::printf("machine: %s; cache %s\n", "2-core shared (see /proc/cpuinfo)", cache.c_str());

  for (int n : sizes) {
    Scene scene = base;
    scene.mesh.target_nodes = n;
    const TetMesh mesh = load_scene_mesh(scene, cache, nullptr);
    const SurfaceMesh surface = boundary_surface(mesh);
    const LiverTensorSetup setup = liver_tensor_setup(scene.material, scene.fixed, mesh, cache, scene.file);
    const int nodes = static_cast<int>(mesh.nodes.rows());
    std::printf("\n=== liver of %d nodes, %zu surface, %zu contactable; tensors %s in %s\n", nodes, surface.nodes.size(),
                setup.contacts.size(), to_string(setup.options.precision), setup.cache_path.c_str());

    // First use: load or build the cache (only the smallest block kept: the build's peak is what matters).
    const ChildResult first = in_child([&](ChildResult& r) {
      CacheOutcome outcome;
      const auto t0 = std::chrono::steady_clock::now();
      load_liver_tensors(setup, mesh, scene.material, {"haptic"}, &std::cerr, &outcome, scene.file);
      r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      r.rebuilt = outcome.rebuilt ? 1 : 0;
    });
    if (!first.ok) throw std::runtime_error(first.error);
    std::printf("first use: %s in %.2f s, peak resident %.0f MiB\n", first.rebuilt ? "precomputed and cached" : "loaded",
                first.seconds, first.peak_mib);

    // Haptic side: the "haptic" block only.
    const ChildResult hap = in_child([&](ChildResult& res) {
      bench::CsvOut tick_csv(out, "node_tick", "", true);
      Tensors tensors = load_liver_tensors(setup, mesh, scene.material, {"haptic"}, &std::cerr);
      res.tensor_mib = static_cast<double>(tensors.bytes()) / (1 << 20);
      const BucketGrid grid(mesh, surface);
      Superposition haptic(tensors, "haptic", kMaxContacts);
      std::printf("\nHaptic tick: continuous collision of the tool segment against the deformed surface (bucket grid, "
                  "candidates evaluated from G), lambda = G_CC^-1 u*, tool force; us\n");
      std::printf("%7s %8s %9s | %8s %8s %8s %8s\n", "nodes", "surface", "contacts", "p50", "p90", "p99", "max");
      // Contacts: the m contactable nodes nearest the top point under the trocar, pushed 5 mm down (a tool pressing
      // a patch); the tool segment moves 1 mm per tick across the patch.
      const Eigen::Vector3d top(0.03, 0.0, 0.042);
      std::vector<std::pair<double, int>> near;
      for (int k : setup.contacts) near.emplace_back((mesh.nodes.row(k).transpose() - top).norm(), k);
      std::sort(near.begin(), near.end());
      for (int m : {1, 5, 10, 20}) {
        std::vector<Contact> contacts;
        for (int l = 0; l < m; ++l) contacts.push_back({near[static_cast<std::size_t>(l)].second, {0, 0, -0.005}});
        ContactSolution sol;
        SampleRecorder rec(static_cast<std::size_t>(reps));
        struct Ctx { const TetMesh* mesh; const Superposition* sp; const ContactSolution* sol; } ctx{&mesh, &haptic, &sol};
        auto deformed = [](const void* c, int node, Eigen::Vector3d& o) {
          const auto* x = static_cast<const Ctx*>(c);
          o = x->mesh->nodes.row(node).transpose();
          Eigen::Vector3d u;
          if (x->sol->count > 0 && x->sp->displacement(node, *x->sol, u)) o += u;
        };
        haptic.solve(contacts.data(), m, sol);
        for (int r = 0; r < reps; ++r) {
          const double s = 0.001 * (r % 20);
          const Eigen::Vector3d p0 = top + Eigen::Vector3d(s - 0.01, 0, 0.01), p1 = p0 + Eigen::Vector3d(0.001, 0, -0.02);
          const std::uint64_t t0 = monotonic_ns();
          const SurfaceHit hit = grid.segment_query(p0, p1, deformed, &ctx);
          contacts[0].displacement.z() = -0.005 - 1e-5 * (r % 7) - (hit.hit ? 0.0 : 1e-9);
          haptic.solve(contacts.data(), m, sol);
          const Eigen::Vector3d f = sol.tool_force;
          rec.add(static_cast<double>(monotonic_ns() - t0) * 1e-3 + 0 * f.x());
        }
        const Percentiles p = rec.summary();
        std::printf("%7d %8zu %9d | %8.2f %8.2f %8.2f %8.2f\n", nodes, surface.nodes.size(), m, p.p50, p.p90, p.p99,
                    p.max);
        tick_csv.row("%d,%zu,%d,%.3f,%.3f,%.3f,%.3f", nodes, surface.nodes.size(), m, p.p50, p.p90, p.p99, p.max);
      }
    });
    if (!hap.ok) throw std::runtime_error(hap.error);

    // Visual side: the "visual" block only; deformation of every visible node for 10 contacts, then the render.
    const ChildResult vis = in_child([&](ChildResult& res) {
      bench::CsvOut deform_csv(out, "node_deform", "", true);
      bench::CsvOut render_csv(out, "node_render", "", true);
      Tensors tensors = load_liver_tensors(setup, mesh, scene.material, {"visual"}, &std::cerr);
      res.tensor_mib = static_cast<double>(tensors.bytes()) / (1 << 20);
      SurfaceDeformer deformer(mesh, surface, &tensors);
      // The same 10 contacts, with forces from a G_CC solve on the visual block (its rows include the contacts).
      const Eigen::Vector3d top(0.03, 0.0, 0.042);
      std::vector<std::pair<double, int>> near;
      for (int k : setup.contacts) near.emplace_back((mesh.nodes.row(k).transpose() - top).norm(), k);
      std::sort(near.begin(), near.end());
      std::vector<Contact> contacts;
      for (int l = 0; l < 10; ++l) contacts.push_back({near[static_cast<std::size_t>(l)].second, {0, 0, -0.005}});
      Superposition solve(tensors, "visual", kMaxContacts);
      ContactSolution sol;
      solve.solve(contacts.data(), 10, sol);
      SampleRecorder rec(static_cast<std::size_t>(reps / 4 + 1));
      for (int r = 0; r < reps / 4; ++r) {
        const std::uint64_t t0 = monotonic_ns();
        deformer.apply(sol.nodes.data(), sol.lambda.data(), sol.count);
        rec.add(static_cast<double>(monotonic_ns() - t0) * 1e-3);
      }
      const Percentiles dp = rec.summary();
      std::printf("\nVisual deformation, u_n = sum_k G_nk lambda_k for every visible node, 10 contacts, us\n");
      std::printf("%8s %8s | %8s %8s %8s\n", "visible", "rows", "p50", "p99", "max");
      std::printf("%8zu %8d | %8.1f %8.1f %8.1f\n", surface.nodes.size(), solve.block().row_count(), dp.p50, dp.p99,
                  dp.max);
      deform_csv.row("%zu,10,%.3f,%.3f,%.3f,%d", surface.nodes.size(), dp.p50, dp.p99, dp.max, nodes);
      if (!render) return;
      std::printf("\nRender (OSMesa llvmpipe, organ %zu visible nodes + tool), ms per frame incl. normals and upload\n",
                  surface.nodes.size());
      std::printf("%10s | %8s %8s %8s %8s\n", "size", "p50", "p99", "max", "fps p50");
      std::vector<std::pair<int, int>> frames = {{640, 480}};
      if (n == sizes.front()) frames.emplace_back(1280, 720);
      for (auto [w, h] : frames) {
        auto renderer = make_renderer("osmesa", w, h);
        ToolGeometry tool = tool_geometry(scene.tools[0], Pose5{0, 0, 0.17, 0, 0.5});
        SampleRecorder rr(200);
        for (int f = 0; f < 120; ++f) {
          deformer.apply(sol.nodes.data(), sol.lambda.data(), sol.count);
          const std::uint64_t t0 = monotonic_ns();
          renderer->begin_frame(scene.visual.camera);
          renderer->draw_surface(deformer.positions(), deformer.tris(), kLiverRgb);
          renderer->draw_tool(tool, static_cast<float>(scene.tools[0].shaft_radius));
          renderer->end_frame();
          if (f >= 20) rr.add(static_cast<double>(monotonic_ns() - t0) * 1e-6);
        }
        const Percentiles p = rr.summary();
        std::printf("%4dx%-5d | %8.2f %8.2f %8.2f %8.1f\n", w, h, p.p50, p.p99, p.max, 1000.0 / p.p50);
        render_csv.row("%d,%d,%zu,%.3f,%.3f,%.3f", w, h, surface.nodes.size(), p.p50, p.p99, p.max);
      }
    });
    if (!vis.ok) throw std::runtime_error(vis.error);
    std::printf("\nPeak resident memory (MiB): first use %.0f (%s), haptic side %.0f (tensors %.0f), visual side %.0f "
                "(tensors %.0f)\n",
                first.peak_mib, first.rebuilt ? "precompute" : "load", hap.peak_mib, hap.tensor_mib, vis.peak_mib,
                vis.tensor_mib);
    memory_csv.row("%d,%zu,%.3f,%d,%.1f,%.1f,%.1f,%.1f,%.1f,%s", nodes, setup.contacts.size(), first.seconds,
                   first.rebuilt, first.peak_mib, hap.peak_mib, hap.tensor_mib, vis.peak_mib, vis.tensor_mib,
                   to_string(setup.options.precision));
  }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "node_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
