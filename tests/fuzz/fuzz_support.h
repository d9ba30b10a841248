// What the fuzz targets share: the input written to a file of this process (for the readers that take a path), and
// the libFuzzer entry point's declaration.
//
// What a target calls a finding: a reader may refuse bad input only with surgsim::core::Error (common/core/error.h:
// "an error a user can act on", whose message names the file, line or key and the fix), which every reader of
// outside input documents as its one failure. A target catches that and nothing else, so any other exception
// (std::bad_alloc, std::out_of_range from .at(), std::invalid_argument from std::stod, a third-party library's
// own exception type, a bare std::runtime_error) escapes the entry point and terminates the run: a finding, as are
// a crash, a leak, undefined behaviour and a hang (libFuzzer's -timeout; the replay's ctest timeout). Readers that
// report through a return value (the caches, the web server's parsers) must never throw at all.
#pragma once
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace surgsim::fuzz {

/// A folder of this process's own under the system's temporary folder (made once, removed at exit), so that two
/// fuzzing processes never share an input file.
inline const std::filesystem::path& scratch_dir() {
  struct Dir {
    std::filesystem::path path;
    Dir() {
      path = std::filesystem::temp_directory_path() / ("surgsim-fuzz-" + std::to_string(::getpid()));
      std::filesystem::create_directories(path);
    }
    ~Dir() {
      std::error_code ec;
      std::filesystem::remove_all(path, ec);
    }
  };
  static const Dir dir;
  return dir.path;
}

/// Writes `bytes` to `name` in the scratch folder (replacing it) and returns the file's path. A failed write aborts:
/// it is the machine's fault, not the input's.
inline std::string write_input(const std::string& name, std::string_view bytes) {
  const std::string path = (scratch_dir() / name).string();
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr || std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size() || std::fclose(f) != 0) {
    std::perror(path.c_str());
    std::abort();
  }
  return path;
}

inline std::string_view as_text(const std::uint8_t* data, std::size_t size) {
  return {reinterpret_cast<const char*>(data), size};
}

}  // namespace surgsim::fuzz
