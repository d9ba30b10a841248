// surgsim-segment: turns a segmented volume (a folder of PNG slices or an NRRD file) into a simulation-ready organ:
// a tetrahedral mesh (PREFIX.msh, PREFIX.vtk), its smooth light surface (PREFIX_surface.vtk) and a scene that uses it
// (PREFIX.yaml). Prints each stage's counts and time.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "imaging/segmentation.h"
#include "imaging/volume_io.h"

using namespace surgsim::core;
using namespace surgsim::mesher;
using namespace surgsim::imaging;

namespace {

using namespace surgsim;

// "sx,sy,sz" in mm -> m.
Eigen::Vector3d parse_spacing(const std::string& text) {
  std::vector<double> v;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      std::size_t used = 0;
      v.push_back(std::stod(item, &used));
      if (used != item.size()) throw std::invalid_argument(item);
    } catch (const std::exception&) {
      throw_error("--spacing '", text, "': expected three numbers in mm, e.g. 0.8,0.8,1.5");
    }
  }
  if (v.size() != 3 || !(v[0] > 0 && v[1] > 0 && v[2] > 0))
    throw_error("--spacing '", text, "': expected three positive numbers in mm, e.g. 0.8,0.8,1.5");
  return Eigen::Vector3d(v[0], v[1], v[2]) * 1e-3;
}

// Refuses (before the work) an output prefix whose folder is missing or not writable.
void check_prefix(const std::string& prefix) {
  namespace fs = std::filesystem;
  const fs::path p(prefix);
  if (p.filename().empty()) throw_error("--out ", prefix, ": give a file prefix, e.g. out/liver");
  const fs::path dir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw_error("--out ", prefix, ": folder ", dir.string(), " does not exist");
  if (::access(dir.c_str(), W_OK) != 0) throw_error("--out ", prefix, ": folder ", dir.string(), " is not writable");
}

}  // namespace

int main(int argc, char** argv) {
  std::string slices, spacing_text, nrrd, out;
  int label = 0;
  bool verbose = false;
  SegmentOptions options;

  CLI::App app{
      "surgsim-segment: builds an organ from a segmented volume (Cotin 1998, section 2). Reads a folder of PNG "
      "slices (grey labels; ordered by the number in their names) or an NRRD volume, selects the organ's label, "
      "extracts its boundary (marching cubes), removes the staircase (Taubin smoothing kept within --max-distance of "
      "the voxel boundary), reduces the triangles adaptively (quadric + curvature edge collapse, same bound), gives "
      "back the volume these stages cut off (an offset along the normals to the labelled voxels' volume, same "
      "bound), and tetrahedralizes inside that surface (Gmsh) at about --nodes nodes. Writes PREFIX.msh, PREFIX.vtk, "
      "PREFIX_surface.vtk and a scene PREFIX.yaml. Coordinates in m (volume spacings are taken in mm)."};
  auto* slices_opt = app.add_option("--slices", slices, "Folder of PNG slices (one per k), e.g. scan/slice_0001.png");
  auto* spacing_opt = app.add_option("--spacing", spacing_text, "Voxel size sx,sy,sz in mm (with --slices)");
  auto* nrrd_opt = app.add_option("--nrrd", nrrd, "NRRD volume: .nrrd (attached) or .nhdr (detached raw data)");
  slices_opt->excludes(nrrd_opt);
  slices_opt->needs(spacing_opt);
  spacing_opt->needs(slices_opt);
  auto* label_opt = app.add_option("--label", label, "Organ label (default: the only non-zero label)");
  app.add_option("--nodes", options.target_nodes,
                 "Tetrahedral mesh nodes, " + std::to_string(kMinOrganNodes) + ".." + std::to_string(kMaxOrganNodes))
      ->capture_default_str();
  app.add_option("--max-distance", options.max_distance,
                 "How far the smooth surface may leave the voxel boundary, in voxels (smallest spacing), (0, 4]")
      ->capture_default_str();
  app.add_option("--surface-error", options.surface_error,
                 "Error bound of the triangle reduction, in voxels, (0, max-distance]")
      ->capture_default_str();
  app.add_option("--smoothing", options.smoothing_iterations, "Taubin lambda|mu iterations, 0..1000")
      ->capture_default_str();
  app.add_option("--denoise", options.denoise,
                 "3x3x3 majority-filter passes on the organ's voxels before meshing (removes flipped voxels and "
                 "one-voxel tunnels of a noisy segmentation; 0 keeps the voxels as they are), 0..10")
      ->capture_default_str();
  app.add_flag("--no-clean", [&options](std::int64_t) { options.clean = false; },
               "Keep stray pieces and cavities (default: keep the largest piece, fill cavities)");
  app.add_option("--out", out, "Output prefix: writes PREFIX.msh, PREFIX.vtk, PREFIX_surface.vtk, PREFIX.yaml")
      ->required();
  app.add_flag("--verbose", verbose, "Print Gmsh's log and each meshing attempt to stderr");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "surgsim-segment: " << e.what() << " (see --help)\n";
    return 2;
  }

  try {
    if (slices.empty() && nrrd.empty()) throw_error("give a volume: --slices DIR --spacing sx,sy,sz or --nrrd FILE");
    if (label_opt->count() > 0) options.label = label;
    check_segment_options(options);
    check_prefix(out);

    const auto t0 = std::chrono::steady_clock::now();
    const LabelVolume volume = nrrd.empty() ? read_png_slices(slices, parse_spacing(spacing_text)) : read_nrrd(nrrd);
    const double read_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const VoxelGrid& g = volume.grid;
    std::printf("read: %s, %d x %d x %d voxels of %.3g x %.3g x %.3g mm (%.2f s)\n", volume.source.c_str(), g.size.x(),
                g.size.y(), g.size.z(), g.spacing.x() * 1e3, g.spacing.y() * 1e3, g.spacing.z() * 1e3, read_s);
    std::fflush(stdout);
    std::cout.precision(3);

    const Segmentation s = segment_volume(volume, options, &std::cout, verbose ? &std::cerr : nullptr);

    const auto t1 = std::chrono::steady_clock::now();
    const SegmentationFiles files = write_segmentation(s, out);
    const double write_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
    const SegmentReport& r = s.report;
    double total = read_s + write_s;
    for (const StageTime& st : r.stages) total += st.seconds;
    std::printf("write: %s, %s, %s, %s (%.2f s)\n", files.msh.c_str(), files.vtk.c_str(), files.surface_vtk.c_str(),
                files.scene.c_str(), write_s);
    std::printf(
        "summary: marching cubes %d triangles -> surface %d (%.1fx fewer) -> mesh boundary %d; %d nodes, %d "
        "tets; volume %.2f cm^3 (labelled voxels %.2f, after the majority filter %.2f, marching cubes %.2f); total "
        "%.2f s\n",
        r.mc_triangles, r.surface.triangles, static_cast<double>(r.mc_triangles) / std::max(1, r.surface.triangles),
        r.boundary.triangles, r.mesh.nodes, r.mesh.tets, r.mesh_volume * 1e6, r.labelled_volume * 1e6,
        r.voxel_volume * 1e6, r.mc_volume * 1e6, total);
  } catch (const std::exception& e) {
    std::cerr << "surgsim-segment: " << e.what() << '\n';
    return 1;
  }
  return 0;
}
