// Fuzz target: Wavefront .obj surfaces (common/mesh/format_obj.cpp, read_obj), the visual surface a scene may name.
// Expected: surgsim::core::Error (see fuzz_support.h); anything else escaping is a finding.
#include "core/error.h"
#include "fuzz_support.h"
#include "mesh/mesh.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace surgsim;
  const std::string path = fuzz::write_input("surface.obj", fuzz::as_text(data, size));
  try {
    (void)mesh::read_obj(path);
  } catch (const core::Error&) {
  }
  return 0;
}
