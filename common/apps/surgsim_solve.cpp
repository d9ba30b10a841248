// surgsim-solve: one static load case of a linear-elastic organ with imposed node displacements (the paper's
// reference computation), by CHOLMOD + Lagrange multipliers, by CG, or by precomputed tensors and superposition.
// The organ may hold regions of other materials (--region), assembled per element.
// Writes DIR/displacement.csv (every node) and DIR/reaction.csv (the imposed nodes).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>

#include "core/error.h"
#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "liver_cli.h"
#include "compliance/precompute.h"
#include "fem/static_solver.h"
#include "compliance/superposition.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::intestine;

namespace {

using namespace surgsim;

// Tensor method: G columns for the imposed nodes only, rows for every node; lambda = G_CC^-1 u*.
StaticSolution solve_by_tensors(const ElasticModel& model, const std::vector<ImposedDisplacement>& imposed) {
  const TetMesh& mesh = *model.mesh;
  const int n = model.node_count();
  std::vector<char> surface(static_cast<std::size_t>(n), 0);
  for (int i : boundary_surface(mesh).nodes) surface[static_cast<std::size_t>(i)] = 1;
  std::vector<Contact> contacts;
  std::vector<int> columns;
  for (const auto& im : imposed) {
    if (im.node < 0 || im.node >= n)
      throw_error("imposed node ", im.node, " is out of range: the mesh has ", n, " nodes (0..", n - 1, ")");
    if (im.components != 7)
      throw_error("--method tensor imposes whole displacements: node ", im.node,
                  " has a free component (use direct or cg for partial constraints)");
    if (!model.fixed.node_fully_free(im.node))
      throw_error("imposed node ", im.node, " is fixed: contacts on fixed nodes are refused");
    if (!surface[static_cast<std::size_t>(im.node)])
      throw_error("imposed node ", im.node,
                  " is not on the surface: tensors exist for surface nodes only (use direct or cg for interior nodes)");
    contacts.push_back({im.node, im.value});
    columns.push_back(im.node);
  }
  std::sort(columns.begin(), columns.end());
  columns.erase(std::unique(columns.begin(), columns.end()), columns.end());
  if (columns.size() > static_cast<std::size_t>(kMaxContacts))
    throw_error("--method tensor takes at most ", kMaxContacts, " distinct imposed nodes, got ", columns.size());
  std::vector<int> all(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) all[static_cast<std::size_t>(i)] = i;
  const Tensors t = precompute_tensors(model, columns, {RowSet{"all", all}}, PrecomputeOptions());
  Superposition s(t, "all", std::max(1, static_cast<int>(columns.size())));
  ContactSolution sol;
  if (s.solve(contacts.data(), static_cast<int>(contacts.size()), sol) != ContactStatus::kOk)
    throw_error("tensor solve failed: ", to_string(sol.status),
                sol.bad_input >= 0 ? " (contact " + std::to_string(sol.bad_input) + ")" : std::string());
  if (sol.duplicate_spread > 0)
    throw_error("a node is imposed twice with different values (they differ by ", sol.duplicate_spread, " m)");
  Eigen::VectorXd u(3 * n);
  s.displacements(sol.nodes.data(), sol.lambda.data(), sol.count, u);
  StaticSolution out;
  out.displacement.resize(n, 3);
  for (int i = 0; i < n; ++i) out.displacement.row(i) = u.segment<3>(3 * i).transpose();
  out.imposed_nodes.assign(sol.nodes.begin(), sol.nodes.begin() + sol.count);
  std::sort(out.imposed_nodes.begin(), out.imposed_nodes.end());
  out.reaction.resize(sol.count, 3);
  for (int l = 0; l < sol.count; ++l) {
    const auto row = std::lower_bound(out.imposed_nodes.begin(), out.imposed_nodes.end(), sol.nodes[static_cast<std::size_t>(l)]) -
                     out.imposed_nodes.begin();
    out.reaction.row(row) = sol.lambda[static_cast<std::size_t>(l)].transpose();
  }
  out.total_reaction = -sol.tool_force;
  return out;
}

void write_csv(const std::string& path, const char* header, const std::vector<int>& nodes, const Eigen::MatrixX3d& v) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) throw_error("cannot write ", path);
  std::fprintf(f, "%s\n", header);
  for (Eigen::Index r = 0; r < v.rows(); ++r)
    std::fprintf(f, "%d,%.17g,%.17g,%.17g\n", nodes.empty() ? static_cast<int>(r) : nodes[static_cast<std::size_t>(r)],
                 v(r, 0), v(r, 1), v(r, 2));
  if (std::fclose(f) != 0) throw_error("writing ", path, " failed");
}

}  // namespace

int main(int argc, char** argv) {
  std::string mesh_file, generate, method = "direct", out_dir;
  int nodes = 1500, max_iter = 0;
  double young = 0, poisson = 0, tol = 1e-10;
  surgsim::apps::cli::FixedOptions fixed_opts;
  std::vector<std::string> imposes, regions;
  bool vtk = false;

  CLI::App app{
      "surgsim-solve: one static load case of a linear-elastic organ with imposed node displacements. Writes "
      "DIR/displacement.csv (node,ux,uy,uz for every node, m) and DIR/reaction.csv (node,fx,fy,fz: the force the "
      "constraint applies on the organ at each imposed node, N). Node indices are 0-based in file order."};
  auto* o_mesh = app.add_option("--mesh", mesh_file, "Tetrahedral mesh (.msh v1/v2/v4 or .vtk)");
  auto* o_gen = app.add_option("--generate", generate, "Generate an organ instead: liver | plate | cylinder");
  o_mesh->excludes(o_gen);
  app.add_option("--nodes", nodes, "Approximate node count of a generated organ")->capture_default_str();
  app.add_option("--young", young, "Young's modulus, Pa")->required();
  app.add_option("--poisson", poisson, "Poisson ratio in [0, 0.5)")->required();
  app.add_option("--region", regions, surgsim::apps::cli::kRegionHelp);
  app.add_option("--fixed", fixed_opts.nodes, "Fixed nodes: 0-based indices i,j,k");
  app.add_option("--fixed-plane", fixed_opts.plane, "Fix nodes with (x - p).n >= 0: px,py,pz,nx,ny,nz (m)");
  app.add_option("--fixed-box", fixed_opts.boxes, "Fix nodes in a box: x0,y0,z0,x1,y1,z1 (m); repeatable");
  app.add_option("--impose", imposes,
                 "NODE:ux,uy,uz imposed displacement (m); repeatable; an empty component stays free (12:,,-0.002)")
      ->required();
  app.add_option("--method", method,
                 "direct (CHOLMOD + Lagrange multipliers) | cg (conjugate gradient) | tensor (precomputed G, "
                 "superposition; surface nodes, whole displacements)")
      ->capture_default_str();
  app.add_option("--tol", tol, "CG relative residual")->capture_default_str();
  app.add_option("--max-iter", max_iter, "CG iteration limit (0: 10 x unknowns)")->capture_default_str();
  app.add_option("--out", out_dir, "Output folder (created)")->required();
  app.add_flag("--vtk", vtk, "Also write DIR/deformed.vtk with the displacement field");
  CLI11_PARSE(app, argc, argv);

  try {
    if (mesh_file.empty() && generate.empty()) throw_error("give the organ with --mesh FILE or --generate SHAPE");
    if (method != "direct" && method != "cg" && method != "tensor")
      throw_error("--method '", method, "': expected direct, cg or tensor");
    std::vector<ImposedDisplacement> imposed;
    for (const auto& s : imposes) imposed.push_back(surgsim::apps::cli::parse_impose(s));
    if (!fixed_opts.any())
      throw_error("no fixed nodes: give --fixed i,j,k, --fixed-plane or --fixed-box (at least 3 non-collinear nodes)");
    Material material;
    material.young_modulus = young;
    material.poisson_ratio = poisson;
    for (const auto& r : regions) material.regions.push_back(surgsim::apps::cli::parse_region(r));
    const TetMesh mesh = surgsim::apps::cli::load_mesh(mesh_file, generate, nodes, &std::cerr);
    const FixedRegion region = surgsim::apps::cli::fixed_region(fixed_opts);
    const FixedSet fixed = fixed_set_from_region(mesh, region);
    const std::string where = mesh_file.empty() ? generate : mesh_file;
    const ElasticModel model = build_elastic_model(mesh, material, fixed, where);

    const auto t0 = std::chrono::steady_clock::now();
    StaticSolution s;
    try {
      if (method == "tensor") {
        s = solve_by_tensors(model, imposed);
      } else {
        StaticSolverOptions opts;
        opts.method = parse_solve_method(method);
        opts.cg_tolerance = tol;
        opts.cg_max_iterations = max_iter;
        StaticSolver solver(model, opts);
        s = solver.solve(imposed);
      }
    } catch (const Error& e) {  // e.g. CHOLMOD: name the mesh
      throw Error(where + ": " + e.what());
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

    std::filesystem::create_directories(out_dir);
    write_csv(out_dir + "/displacement.csv", "node,ux,uy,uz", {}, s.displacement);
    write_csv(out_dir + "/reaction.csv", "node,fx,fy,fz", s.imposed_nodes, s.reaction);
    if (vtk) write_vtk(out_dir + "/deformed.vtk", mesh, &s.displacement);
    if (!material.regions.empty()) {
      std::vector<int> count(model.elements.materials.size(), 0);
      for (int i : model.elements.element) ++count[static_cast<std::size_t>(i)];
      std::printf("materials: %d tets base", count[0]);
      for (std::size_t r = 0; r < material.regions.size(); ++r)
        std::printf(", %d tets %s", count[r + 1], material.regions[r].name.c_str());
      std::printf("\n");
    }
    std::printf("%s: %d nodes, %zu imposed, max |u| %.6g m, total reaction (%.6g, %.6g, %.6g) N, %.3f s", method.c_str(),
                model.node_count(), s.imposed_nodes.size(), s.displacement.rowwise().norm().maxCoeff(),
                s.total_reaction.x(), s.total_reaction.y(), s.total_reaction.z(), seconds);
    if (method == "cg") std::printf(", %d iterations, residual %.2e", s.iterations, s.residual);
    std::printf("\n");
    if (!s.converged) {
      std::fprintf(stderr, "surgsim-solve: CG did not reach --tol %g in %d iterations (residual %.2e)\n", tol,
                   s.iterations, s.residual);
      return 3;
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "surgsim-solve: %s\n", e.what());
    return 1;
  }
}
