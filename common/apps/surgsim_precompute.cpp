// surgsim-precompute: builds the liver tensor cache (G = K_ff^-1 restricted to the contactable columns and to the
// haptic and visual rows) for a mesh or a scene, and writes it to --out. An up-to-date cache is left alone.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>

#include "core/error.h"
#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "liver_cli.h"
#include "liver/liver_setup.h"
#include "compliance/precompute.h"
#include "compliance/tensor_cache.h"
#include "mesher/scene_mesh.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::liver;
using namespace surgsim::intestine;
using namespace surgsim::scene;
using namespace surgsim::mesher;

int main(int argc, char** argv) {
  using namespace surgsim;
  std::string mesh_file, generate, scene_file, out, precision = "auto", method = "direct";
  int nodes = 1500, max_iter = 0, block = PrecomputeOptions().block_columns, threads = 0;
  double young = -1, poisson = -1, tol = 1e-10, memory_limit_mb = 4096;
  surgsim::apps::cli::FixedOptions fixed_opts;
  std::vector<std::string> regions;
  bool force = false, quiet = false;

  CLI::App app{
      "surgsim-precompute: factors the free-free stiffness of a linear-elastic organ once (CHOLMOD) and solves the "
      "responses to unit forces on every contactable (free surface) node; keeps the haptic rows (surface x surface) "
      "and the visual rows (boundary x surface) and writes them to a tensor cache. Progress goes to stderr."};
  auto* o_mesh = app.add_option("--mesh", mesh_file, "Tetrahedral mesh (.msh v1/v2/v4 or .vtk)");
  auto* o_gen = app.add_option("--generate", generate, "Generate an organ instead: liver | plate | cylinder");
  auto* o_scene = app.add_option("--scene", scene_file, "Scene YAML (mesh, material and fixed region from it)");
  o_mesh->excludes(o_gen)->excludes(o_scene);
  o_gen->excludes(o_scene);
  app.add_option("--nodes", nodes, "Approximate node count of a generated organ")->capture_default_str();
  auto* o_young = app.add_option("--young", young, "Young's modulus, Pa (required unless --scene)");
  auto* o_poisson = app.add_option("--poisson", poisson, "Poisson ratio in [0, 0.5) (required unless --scene)");
  auto* o_fixed = app.add_option("--fixed", fixed_opts.nodes, "Fixed nodes: 0-based indices i,j,k");
  auto* o_plane = app.add_option("--fixed-plane", fixed_opts.plane,
                                 "Fix nodes with (x - p).n >= 0: px,py,pz,nx,ny,nz (m)");
  auto* o_box = app.add_option("--fixed-box", fixed_opts.boxes, "Fix nodes in a box: x0,y0,z0,x1,y1,z1 (m); repeatable");
  auto* o_region = app.add_option("--region", regions, surgsim::apps::cli::kRegionHelp);
  for (auto* o : {o_young, o_poisson, o_fixed, o_plane, o_box, o_region}) o->excludes(o_scene);
  app.add_option("--out", out, "Tensor cache file to write")->required();
  app.add_option("--precision", precision,
                 "Stored precision: float | double | auto (as the scenes: double unless it passes 1 GiB)")
      ->capture_default_str();
  app.add_option("--method", method, "direct (CHOLMOD, blocks of right-hand sides) | cg (one CG solve per column)")
      ->capture_default_str();
  app.add_option("--tol", tol, "CG relative residual per column")->capture_default_str();
  app.add_option("--max-iter", max_iter, "CG iteration limit per column (0: 10 x unknowns)")->capture_default_str();
  app.add_option("--block", block, "Unit right-hand sides per blocked supernodal solve")->capture_default_str();
  app.add_option("--threads", threads, "Solving threads (0: every core; the result does not depend on it)")
      ->capture_default_str();
  app.add_option("--memory-limit-mb", memory_limit_mb, "Refuse when the memory estimate exceeds this many MiB (0: no limit)")
      ->capture_default_str();
  app.add_flag("--force", force, "Recompute even if the cache is up to date");
  app.add_flag("--quiet", quiet, "No progress output");
  CLI11_PARSE(app, argc, argv);

  try {
    if (mesh_file.empty() && generate.empty() && scene_file.empty())
      throw_error("give the organ with --mesh FILE, --generate SHAPE or --scene FILE");
    TetMesh mesh;
    Material material;
    FixedRegion region;
    std::string where;
    if (!scene_file.empty()) {
      const Scene scene = load_scene(resolve_scene_path(scene_file));
      if (scene.model != "liver") throw_error(scene.file, ": model '", scene.model, "' has no tensors (liver only)");
      mesh = load_scene_mesh(scene, default_cache_dir(), quiet ? nullptr : &std::cerr);
      material = scene.material;
      region = scene.fixed;
      where = scene.file;
    } else {
      if (young < 0 || poisson < 0) throw_error("--young and --poisson are required with --mesh or --generate");
      material.young_modulus = young;
      material.poisson_ratio = poisson;
      for (const auto& r : regions) material.regions.push_back(surgsim::apps::cli::parse_region(r));
      if (!fixed_opts.any())
        throw_error("no fixed nodes: give --fixed i,j,k, --fixed-plane or --fixed-box (at least 3 non-collinear nodes)");
      region = surgsim::apps::cli::fixed_region(fixed_opts);
      mesh = surgsim::apps::cli::load_mesh(mesh_file, generate, nodes, quiet ? nullptr : &std::cerr);
      where = mesh_file.empty() ? "generated " + generate : mesh_file;
    }
    const FixedSet fixed = fixed_set_from_region(mesh, region);
    const ElasticModel model = build_elastic_model(mesh, material, fixed, where);
    const std::vector<int> contacts = contactable_nodes(mesh, fixed);
    if (contacts.empty()) throw_error(where, ": no free surface node to precompute (everything is fixed?)");
    const std::vector<RowSet> rows = standard_row_sets(mesh, fixed, contacts);

    // As the scenes store them: the haptic block (contacts x contacts) as one half, float only when large.
    PrecomputeOptions opts = scene_precompute_options(static_cast<int>(contacts.size()), rows);
    if (precision != "auto") opts.precision = parse_precision(precision);
    opts.threads = threads;
    opts.method = parse_solve_method(method);
    opts.cg_tolerance = tol;
    opts.cg_max_iterations = max_iter;
    opts.block_columns = block;
    opts.memory_limit_mb = memory_limit_mb;
    surgsim::apps::cli::ProgressPrinter printer(quiet);
    opts.progress = [&](const PrecomputeProgress& p) { printer(p); };

    const TensorCacheKey key = tensor_cache_key(mesh, material, fixed, contacts, rows, opts);
    if (!force) {
      Tensors existing;
      const CacheLoad load = load_tensor_cache(out, key, existing, {});
      if (load.status == CacheStatus::kOk) {
        std::printf("%s is up to date (%d nodes, %d contactable); nothing to do (--force recomputes)\n", out.c_str(),
                    existing.node_count, existing.column_count());
        return 0;
      }
      if (load.status != CacheStatus::kMissing && !quiet)
        std::fprintf(stderr, "precompute: %s is %s (%s): rebuilding\n", out.c_str(), to_string(load.status),
                     load.detail.c_str());
    }
    if (!quiet)
      std::fprintf(stderr, "precompute: %d nodes, %d tets, %d fixed, %d contactable -> %d columns; estimate %s\n",
                   model.node_count(), static_cast<int>(mesh.tets.rows()),
                   static_cast<int>(fixed.fixed_nodes().size()), static_cast<int>(contacts.size()),
                   3 * static_cast<int>(contacts.size()),
                   estimate_precompute_memory(model, static_cast<int>(contacts.size()), rows, opts).describe().c_str());
    PrecomputeReport report;
    Tensors tensors;
    try {
      tensors = precompute_tensors(model, contacts, rows, opts, &report);
    } catch (const Error& e) {  // e.g. CHOLMOD: name the scene and its mesh file
      const bool other_mesh = !mesh.source.empty() && mesh.source != where;
      throw Error(where + (other_mesh ? " (mesh " + mesh.source + ")" : "") + ": " + e.what());
    }
    save_tensor_cache(out, tensors, key);
    std::printf("wrote %s: %d nodes, %d contactable, blocks haptic %d x %d and visual %d x %d (%s), %.1f MiB\n",
                out.c_str(), tensors.node_count, tensors.column_count(), tensors.blocks[0].row_count(),
                tensors.column_count(), tensors.blocks[1].row_count(), tensors.column_count(), to_string(opts.precision),
                static_cast<double>(std::filesystem::file_size(out)) / (1024.0 * 1024.0));
    std::printf("method %s: analyze %.3f s, factor %.3f s, solve %.3f s (%d thread(s)), total %.3f s",
                to_string(opts.method), report.analyze_s, report.factor_s, report.solve_s, report.threads, report.total_s);
    if (opts.method == SolveMethod::kCg)
      std::printf("; CG max %d iterations, worst residual %.2e%s", report.cg_max_iterations, report.cg_max_residual,
                  report.cg_all_converged ? "" : " (some columns hit the iteration limit)");
    std::printf("\n");
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "surgsim-precompute: %s\n", e.what());
    return 1;
  }
}
