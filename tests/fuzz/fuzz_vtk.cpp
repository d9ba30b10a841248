// Fuzz target: legacy VTK unstructured grids (common/mesh/format_vtk.cpp, read_vtk), then validated as
// fuzz_tet_mesh.h says.
// Expected: surgsim::core::Error (see fuzz_support.h); anything else escaping is a finding.
#include "fuzz_tet_mesh.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  surgsim::fuzz::read_tet_mesh(surgsim::mesh::read_vtk, "mesh.vtk", data, size);
  return 0;
}
