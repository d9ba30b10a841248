// Fuzz target: NRRD volumes (common/imaging/volume_io.cpp, read_nrrd). The input is an attached .nrrd; a header
// without data is read as a detached one whose `data file:` the input names (data.raw, an empty file beside it, is
// offered through the dictionary).
// Expected: surgsim::core::Error (see fuzz_support.h); anything else escaping is a finding.
#include "core/error.h"
#include "fuzz_support.h"
#include "imaging/volume_io.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace surgsim;
  static const std::string raw = fuzz::write_input("data.raw", std::string(64, '\1'));
  (void)raw;
  const std::string path = fuzz::write_input("volume.nrrd", fuzz::as_text(data, size));
  try {
    (void)imaging::read_nrrd(path);
  } catch (const core::Error&) {
  }
  return 0;
}
