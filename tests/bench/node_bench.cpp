// node_bench: the run-phase costs of both nodes on generated livers, measured side by side in one run.
//   haptic tick (collision on the deformed surface + G_CC solve + force) against contact count and mesh size;
//   visual deformation of every visible node against mesh size; render time at 640x480 and 1280x720.
// A plain program printing tables (run by hand, never a pass/fail test):
//   build/bench/node_bench [--sizes 1500,5000] [--reps 2000] [--no-render] [--out DIR]
// --out DIR also writes node_tick.csv, node_deform.csv and node_render.csv there (scripts/report.sh).
// Tensors come from the shared cache ($SURGSIM_CACHE_DIR), built on first use (20k nodes: ~1.5 min, ~4 GB).
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <random>

#include "core/clock.h"
#include "csv_out.h"
#include "liver/bucket_grid.h"
#include "organs/liver_contacts.h"
#include "liver/liver_setup.h"
#include "mesher/organ_mesher.h"
#include "render/renderer.h"
#include "scene/scene.h"
#include "mesher/scene_mesh.h"
#include "core/stats.h"
#include "views/surface_deformer.h"

using namespace surgsim;

namespace {

struct Row {
  int nodes = 0, surface = 0, contacts = 0;
  Percentiles tick;
};

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> sizes = {1500, 5000};
  int reps = 2000;
  bool render = true;
  std::string out;
  CLI::App cli{"surgsim node benchmarks: haptic tick against contacts and mesh size, visual deformation and render "
               "times (percentiles, side by side in one run)."};
  cli.add_option("--sizes", sizes, "Liver node counts (generated)")->delimiter(',')->capture_default_str();
  cli.add_option("--reps", reps, "Repetitions per measurement")->capture_default_str();
  cli.add_flag("!--no-render", render, "Skip the OSMesa render timings");
  cli.add_option("--out", out, "Also write the tables as CSV files into this existing folder");
  CLI11_PARSE(cli, argc, argv);
  try {
  bench::CsvOut tick_csv(out, "node_tick", "nodes,surface_nodes,contacts,tick_us_p50,tick_us_p90,tick_us_p99,tick_us_max");
  bench::CsvOut deform_csv(out, "node_deform", "visible_nodes,contacts,deform_us_p50,deform_us_p99,deform_us_max");
  bench::CsvOut render_csv(out, "node_render", "width,height,visible_nodes,frame_ms_p50,frame_ms_p99,frame_ms_max");

  const Scene base = load_scene(resolve_scene_path("liver"));
  const std::string cache = default_cache_dir();
  std::printf("machine: %s; cache %s\n", "2-core shared (see /proc/cpuinfo)", cache.c_str());
  std::printf("\nHaptic tick: continuous collision of the tool segment against the deformed surface (bucket grid, "
              "candidates evaluated from G), lambda = G_CC^-1 u*, tool force; us\n");
  std::printf("%7s %8s %9s | %8s %8s %8s %8s\n", "nodes", "surface", "contacts", "p50", "p90", "p99", "max");

  std::vector<std::pair<int, Percentiles>> deform_rows;
  for (int n : sizes) {
    Scene scene = base;
    scene.mesh.target_nodes = n;
    TetMesh mesh = load_scene_mesh(scene, cache, nullptr);
    const SurfaceMesh surface = boundary_surface(mesh);
    const LiverTensorSetup setup = liver_tensor_setup(scene.material, scene.fixed, mesh, cache, scene.file);
    Tensors tensors = load_liver_tensors(setup, mesh, scene.material, {"haptic", "visual"}, &std::cerr);
    const BucketGrid grid(mesh, surface);
    Superposition haptic(tensors, "haptic", kMaxContacts);

    // Contacts: the m contactable nodes nearest the top point under the trocar, pushed 5 mm down (a tool pressing a
    // patch); the tool segment moves 1 mm per tick across the patch.
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
      auto deformed = [](const void* c, int node, Eigen::Vector3d& out) {
        const auto* x = static_cast<const Ctx*>(c);
        out = x->mesh->nodes.row(node).transpose();
        Eigen::Vector3d u;
        if (x->sol->count > 0 && x->sp->displacement(node, *x->sol, u)) out += u;
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
      std::printf("%7d %8zu %9d | %8.2f %8.2f %8.2f %8.2f\n", static_cast<int>(mesh.nodes.rows()), surface.nodes.size(),
                  m, p.p50, p.p90, p.p99, p.max);
      tick_csv.row("%d,%zu,%d,%.3f,%.3f,%.3f,%.3f", static_cast<int>(mesh.nodes.rows()), surface.nodes.size(), m, p.p50,
                   p.p90, p.p99, p.max);
    }

    // Visual deformation of every visible node for 10 contacts.
    SurfaceDeformer deformer(mesh, surface, &tensors);
    std::vector<Contact> contacts;
    for (int l = 0; l < 10; ++l) contacts.push_back({near[static_cast<std::size_t>(l)].second, {0, 0, -0.005}});
    ContactSolution sol;
    haptic.solve(contacts.data(), 10, sol);
    SampleRecorder rec(static_cast<std::size_t>(reps / 4 + 1));
    for (int r = 0; r < reps / 4; ++r) {
      const std::uint64_t t0 = monotonic_ns();
      deformer.apply(sol.nodes.data(), sol.lambda.data(), sol.count);
      rec.add(static_cast<double>(monotonic_ns() - t0) * 1e-3);
    }
    deform_rows.emplace_back(static_cast<int>(surface.nodes.size()), rec.summary());

    if (render && n == sizes.front()) {
      std::printf("\nRender (OSMesa llvmpipe, organ %zu visible nodes + tool), ms per frame incl. normals and upload\n",
                  surface.nodes.size());
      std::printf("%10s | %8s %8s %8s\n", "size", "p50", "p99", "max");
      for (auto [w, h] : {std::pair{640, 480}, std::pair{1280, 720}}) {
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
        std::printf("%4dx%-5d | %8.2f %8.2f %8.2f\n", w, h, p.p50, p.p99, p.max);
        render_csv.row("%d,%d,%zu,%.3f,%.3f,%.3f", w, h, surface.nodes.size(), p.p50, p.p99, p.max);
      }
      std::printf("\nHaptic tick table continues:\n");
    }
  }
  std::printf("\nVisual deformation, u_n = sum_k G_nk lambda_k for every visible node, 10 contacts, us\n");
  std::printf("%8s | %8s %8s %8s\n", "visible", "p50", "p99", "max");
  for (const auto& [v, p] : deform_rows) {
    std::printf("%8d | %8.1f %8.1f %8.1f\n", v, p.p50, p.p99, p.max);
    deform_csv.row("%d,10,%.3f,%.3f,%.3f", v, p.p50, p.p99, p.max);
  }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "node_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
