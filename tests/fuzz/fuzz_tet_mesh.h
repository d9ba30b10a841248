// What the tetrahedral mesh targets (fuzz_msh, fuzz_vtk) do with an input: written as `file_name`, read by `read`,
// then what every loaded mesh goes through: validate_mesh (with orientation repair, as the scenes load it), its
// boundary and hash.
// Expected: surgsim::core::Error (see fuzz_support.h); anything else escaping is a finding.
#pragma once
#include <string>

#include "core/error.h"
#include "fuzz_support.h"
#include "mesh/mesh.h"

namespace surgsim::fuzz {

inline void read_tet_mesh(mesh::TetMesh (*read)(const std::string&), const char* file_name, const std::uint8_t* data,
                          std::size_t size) {
  const std::string path = write_input(file_name, as_text(data, size));
  try {
    mesh::TetMesh m = read(path);
    mesh::validate_mesh(m);
    (void)mesh::boundary_surface(m);
    (void)mesh::mesh_hash(m);
  } catch (const core::Error&) {
  }
}

}  // namespace surgsim::fuzz
