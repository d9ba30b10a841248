// Fuzz target: Gmsh .msh meshes, v1, v2 and v4 ASCII (common/mesh/format_msh.cpp, read_msh), then validated as
// fuzz_tet_mesh.h says.
// Expected: surgsim::core::Error (see fuzz_support.h); anything else escaping is a finding.
#include "fuzz_tet_mesh.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  surgsim::fuzz::read_tet_mesh(surgsim::mesh::read_msh, "mesh.msh", data, size);
  return 0;
}
