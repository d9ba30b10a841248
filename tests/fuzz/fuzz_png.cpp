// Fuzz target: PNG slices (common/imaging/volume_io.cpp, read_png_slices through libpng). The input is the one
// slice of a folder (slice_000.png). The target seals it first: each whole chunk's CRC is recomputed (a mutation
// cannot keep one right by chance, and libpng refuses a chunk whose CRC is wrong before the reader sees it).
// Expected: surgsim::core::Error (see fuzz_support.h); anything else escaping is a finding.
#include <zlib.h>

#include <filesystem>
#include <string>

#include "core/error.h"
#include "fuzz_support.h"
#include "imaging/volume_io.h"

namespace {

std::uint32_t be32(const std::string& b, std::size_t at) {
  return static_cast<std::uint32_t>(static_cast<unsigned char>(b[at])) << 24 |
         static_cast<std::uint32_t>(static_cast<unsigned char>(b[at + 1])) << 16 |
         static_cast<std::uint32_t>(static_cast<unsigned char>(b[at + 2])) << 8 |
         static_cast<std::uint32_t>(static_cast<unsigned char>(b[at + 3]));
}

// The CRC of every chunk that lies wholly in the bytes after the 8-byte signature (length, type, data, CRC).
void seal_chunks(std::string& b) {
  std::size_t at = 8;
  while (at + 12 <= b.size()) {
    const std::uint32_t length = be32(b, at);
    if (length > b.size() - at - 12) break;
    const auto* typed = reinterpret_cast<const Bytef*>(b.data() + at + 4);
    const std::uint32_t crc = static_cast<std::uint32_t>(crc32(0L, typed, static_cast<uInt>(length + 4)));
    for (int k = 0; k < 4; ++k)
      b[at + 8 + length + static_cast<std::size_t>(k)] = static_cast<char>(crc >> (24 - 8 * k));
    at += 12 + length;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace surgsim;
  static const std::string folder = [] {
    const auto dir = fuzz::scratch_dir() / "slices";
    std::filesystem::create_directories(dir);
    return dir.string();
  }();
  std::string bytes(fuzz::as_text(data, size));
  seal_chunks(bytes);
  fuzz::write_input("slices/slice_000.png", bytes);
  try {
    (void)imaging::read_png_slices(folder, Eigen::Vector3d(1e-3, 1e-3, 1e-3));
  } catch (const core::Error&) {
  }
  return 0;
}
