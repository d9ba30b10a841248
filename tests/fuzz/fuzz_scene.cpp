// Fuzz target: scene YAML (common/scene/scene.cpp, load_scene), and the scene hash both nodes compare.
// The input is the scene file; beside it lie empty files the scene may name (mesh.msh, mesh.vtk, curve.csv,
// trajectory.csv, surface.obj), since load_scene checks that referenced files exist but does not read them.
// Expected: surgsim::core::Error (see fuzz_support.h); anything else escaping is a finding.
#include "core/error.h"
#include "fuzz_support.h"
#include "scene/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace surgsim;
  static const bool files_made = [] {
    for (const char* name : {"mesh.msh", "mesh.vtk", "curve.csv", "trajectory.csv", "surface.obj"})
      fuzz::write_input(name, "");
    return true;
  }();
  (void)files_made;
  const std::string path = fuzz::write_input("scene.yaml", fuzz::as_text(data, size));
  try {
    const scene::Scene s = scene::load_scene(path);
    (void)s.hash();
  } catch (const core::Error&) {
  }
  return 0;
}
