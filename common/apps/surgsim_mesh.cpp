// surgsim-mesh: generates an organ (liver-shaped solid, plate or cylinder) as a linear tetrahedral mesh with about
// the requested node count, and writes it as a Gmsh v2.2 .msh (and optionally a VTK .vtk).
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>

#include "core/error.h"
#include "mesh/mesh.h"
#include "mesher/organ_mesher.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::mesher;

namespace {

using namespace surgsim;

// Refuses (before meshing, which may take a while) an output path whose folder is missing or not writable, or
// whose name lacks the expected extension.
void check_output(const std::string& option, const std::string& path, const std::string& extension) {
  namespace fs = std::filesystem;
  const fs::path p(path);
  if (p.extension() != extension) throw_error(option, " ", path, ": the file name must end in ", extension);
  const fs::path dir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw_error(option, " ", path, ": folder ", dir.string(), " does not exist");
  if (::access(dir.c_str(), W_OK) != 0) throw_error(option, " ", path, ": folder ", dir.string(), " is not writable");
  if (fs::exists(p, ec) && (fs::is_directory(p, ec) || ::access(p.c_str(), W_OK) != 0))
    throw_error(option, " ", path, ": exists and cannot be overwritten");
}

}  // namespace

int main(int argc, char** argv) {
  OrganSpec spec;
  std::string out, vtk;
  bool verbose = false;

  CLI::App app{
      "surgsim-mesh: generates an organ as a linear tetrahedral mesh (Gmsh) with about the requested node count "
      "(within +-20 % from 500 nodes up; deterministic) and writes it as a Gmsh v2.2 .msh. Shapes (m, z up): "
      "liver (lobed solid about 0.26 x 0.16 x 0.08, flat underside near z = -0.035), plate (0.20 x 0.20 x 0.01, "
      "centred), cylinder (radius 0.025, height 0.10, base at z = 0)."};
  app.add_option("--shape", spec.shape, "liver | plate | cylinder")->required();
  app.add_option("--nodes", spec.target_nodes,
                 "Approximate node count, " + std::to_string(kMinOrganNodes) + ".." + std::to_string(kMaxOrganNodes))
      ->capture_default_str();
  app.add_option("--out", out, "Output mesh, FILE.msh (Gmsh v2.2 ASCII)")->required();
  app.add_option("--vtk", vtk, "Also write the mesh as FILE.vtk (VTK legacy ASCII)");
  app.add_flag("--verbose", verbose, "Print each meshing attempt and Gmsh's log to stderr");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "surgsim-mesh: " << e.what() << " (see --help)\n";
    return 2;
  }

  try {
    check_organ_spec(spec);
    check_output("--out", out, ".msh");
    if (!vtk.empty()) check_output("--vtk", vtk, ".vtk");

    OrganMeshReport report;
    const TetMesh mesh = generate_organ(spec, verbose ? &std::cerr : nullptr, &report);
    write_msh(out, mesh);
    if (!vtk.empty()) write_vtk(vtk, mesh);
    std::printf("%s: %d nodes (target %d), %d tets, h = %.2f mm, %d meshing(s), worst tet quality %.2f, %.2f s -> %s\n",
                spec.shape.c_str(), report.nodes, spec.target_nodes, report.tets, report.mesh_size * 1000.0,
                report.attempts, report.min_quality, report.seconds, out.c_str());
  } catch (const std::exception& e) {
    std::cerr << "surgsim-mesh: " << e.what() << '\n';
    return 1;
  }
  return 0;
}
