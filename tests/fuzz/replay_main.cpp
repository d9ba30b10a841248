// Replays inputs through a fuzz target without libFuzzer (the normal build's ctest fuzz_replay_<target>): every
// file of each folder given (in name order; names starting with '.' skipped) or each file given is passed once to
// LLVMFuzzerTestOneInput. A finding ends the run as it would under libFuzzer (an escaped exception terminates, a
// sanitizer build reports), and the input's name is printed before it runs, so the log says which input it was.
//
// Usage: <target> PATH...   exit 0 when every input ran; 2 when a path does not exist or no input was found.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "fuzz_support.h"

namespace fs = std::filesystem;

namespace {

int replay(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) {
    std::fprintf(stderr, "replay: cannot read %s\n", file.c_str());
    return 1;
  }
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::printf("replay: %s (%zu bytes)\n", file.c_str(), bytes.size());
  std::fflush(stdout);
  LLVMFuzzerTestOneInput(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<fs::path> inputs;
  for (int i = 1; i < argc; ++i) {
    const fs::path p(argv[i]);
    std::error_code ec;
    if (fs::is_directory(p, ec)) {
      std::vector<fs::path> files;
      for (const auto& e : fs::directory_iterator(p)) {
        if (e.is_regular_file() && e.path().filename().string().front() != '.') files.push_back(e.path());
      }
      std::sort(files.begin(), files.end());
      inputs.insert(inputs.end(), files.begin(), files.end());
    } else if (fs::is_regular_file(p, ec)) {
      inputs.push_back(p);
    } else {
      std::fprintf(stderr, "replay: %s is neither a folder nor a file (give the corpus or regression folder)\n",
                   argv[i]);
      return 2;
    }
  }
  if (inputs.empty()) {
    std::fprintf(stderr, "replay: no input in the paths given (a corpus folder holds at least one seed)\n");
    return 2;
  }
  int failed = 0;
  for (const auto& f : inputs) failed += replay(f);
  std::printf("replay: %zu inputs, %d unreadable\n", inputs.size(), failed);
  return failed == 0 ? 0 : 1;
}
