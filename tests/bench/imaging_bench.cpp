// imaging_bench: the segmentation round trip's figures. Voxelizes the generated liver at each requested voxel size,
// clean and with seeded noise, rebuilds it (surgsim_imaging's pipeline) and prints, per case, the symmetric
// Hausdorff and mean distances to the original surface in voxels (plain marching cubes, the smooth light surface,
// the tetrahedral mesh's boundary), their triangle counts, the volume errors and the time of each stage. Run by hand
// (not a ctest); --volumes DIR also writes each test volume as NRRD and PNG slices for surgsim-segment.
#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "common/imaging/imaging_test_util.h"
#include "imaging/segmentation.h"
#include "imaging/volume_io.h"

using namespace surgsim::imaging;

namespace {

using namespace surgsim;

double since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<double> spacings_mm = {1.5, 3.0};
  int reference_nodes = 5000;
  double noise = 0.3;
  int speckles = 20;
  unsigned seed = 1;
  std::string volumes;
  SegmentOptions options;
  CLI::App app{"imaging_bench: round-trip figures of the segmentation pipeline on the voxelized generated liver"};
  app.add_option("--spacing", spacings_mm, "Voxel sizes, mm")->delimiter(',')->capture_default_str();
  app.add_option("--reference-nodes", reference_nodes, "Node count of the generated liver (the original)")
      ->capture_default_str();
  app.add_option("--nodes", options.target_nodes, "Node count of the rebuilt tetrahedral mesh")->capture_default_str();
  app.add_option("--max-distance", options.max_distance, "Bound to the voxel boundary, voxels")->capture_default_str();
  app.add_option("--surface-error", options.surface_error, "Reduction error bound, voxels")->capture_default_str();
  app.add_option("--smoothing", options.smoothing_iterations, "Taubin iterations")->capture_default_str();
  app.add_option("--noise", noise, "Probability of flipping a boundary voxel in the noisy cases")->capture_default_str();
  app.add_option("--speckles", speckles, "Stray foreground voxels in the noisy cases")->capture_default_str();
  app.add_option("--seed", seed, "Noise seed")->capture_default_str();
  app.add_option("--volumes", volumes, "Also write the test volumes here (NRRD + PNG slices)");
  CLI11_PARSE(app, argc, argv);

  try {
    auto t0 = std::chrono::steady_clock::now();
    const test::ReferenceOrgan reference = test::reference_liver(reference_nodes);
    std::printf("original: generated liver, %ld nodes, %ld boundary triangles, %.1f cm^3 (%.2f s)\n\n",
                static_cast<long>(reference.mesh.nodes.rows()), static_cast<long>(reference.surface.tris.rows()),
                reference.volume * 1e6, since(t0));
    std::printf("%-16s %9s | %9s %9s %9s | %7s %7s %7s %7s %7s %7s | %7s %7s %7s | %6s %6s %6s %6s %6s %6s\n",
                "case", "voxels", "MC tris", "surf tris", "mesh tris", "MC H", "MC mean", "surf H", "surf m",
                "mesh H", "mesh m", "dV MC", "dV surf", "dV mesh", "select", "MC", "smooth", "reduce", "tets",
                "total");
    for (double mm : spacings_mm) {
      for (bool noisy : {false, true}) {
        const double spacing = mm * 1e-3;
        const LabelVolume volume =
            test::liver_volume(reference, spacing, noisy ? noise : 0.0, noisy ? speckles : 0, seed);
        char name[64];
        std::snprintf(name, sizeof name, "%.1f mm%s", mm, noisy ? " noisy" : "");
        if (!volumes.empty()) {
          char stem[64];
          std::snprintf(stem, sizeof stem, "liver_%.1fmm%s", mm, noisy ? "_noisy" : "");
          const std::filesystem::path dir(volumes);
          std::filesystem::create_directories(dir);
          write_nrrd(volume, (dir / (std::string(stem) + ".nrrd")).string());
          write_png_slices(volume, (dir / stem).string());
        }
        const Segmentation s = segment_volume(volume, options);
        const test::RoundTrip r = test::round_trip(reference, s, spacing);
        double total = 0.0;
        for (const StageTime& st : s.report.stages) total += st.seconds;
        std::printf("%-16s %9ld | %9d %9d %9d | %7.2f %7.2f %7.2f %7.2f %7.2f %7.2f | %+6.2f%% %+6.2f%% %+6.2f%% |",
                    name, static_cast<long>(volume.labels.size()), r.mc_triangles, r.surface_triangles,
                    r.mesh_triangles, r.mc_hausdorff, r.mc_mean, r.surface_hausdorff, r.surface_mean,
                    r.mesh_hausdorff, r.mesh_mean, 100 * r.mc_volume_error, 100 * r.surface_volume_error,
                    100 * r.mesh_volume_error);
        for (const StageTime& st : s.report.stages) std::printf(" %6.2f", st.seconds);
        std::printf(" %6.2f\n", total);
        std::printf("%-16s mesh %d nodes (wanted %d), %d tets, worst tet quality %.2f; majority filter changed %ld "
                    "voxels, %ld stray voxels dropped, %ld cavity voxels filled; smoothing clamped %ld moves\n",
                    "", s.report.mesh.nodes, options.target_nodes, s.report.mesh.tets, s.report.mesh.min_quality,
                    static_cast<long>(s.report.denoised_voxels), static_cast<long>(s.report.cleanup.removed_voxels),
                    static_cast<long>(s.report.cleanup.filled_voxels), s.report.smoothing.clamped);
      }
    }
    std::printf("\nH: symmetric Hausdorff distance, m: mean distance, both to the original surface in voxels of the "
                "case; dV: volume error against the original; times in s.\n");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "imaging_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
