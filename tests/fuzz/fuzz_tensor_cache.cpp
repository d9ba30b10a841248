// Fuzz target: the tensor cache (common/compliance/tensor_cache.cpp, load_tensor_cache), then a read of every
// block's corner entries as the contact code reads them.
// The target seals the input before writing it: what a mutation cannot keep consistent by chance is recomputed as
// save_tensor_cache writes it - the payload size and checksum, the header checksum - and the expected key is the
// one the file carries, so the fuzzer's inputs reach the parsing of the counts and blocks (a stale or damaged file
// is refused before that, by comparisons these fields decide).
// Expected: none. load_tensor_cache reports a bad file through CacheLoad and never throws, so any exception escaping
// is a finding (see fuzz_support.h).
#include <cstring>
#include <string>

#include "compliance/tensor_cache.h"
#include "fuzz_support.h"

namespace {

// Offsets of the header's fields (compliance/tensor_cache.h, the layout).
constexpr std::size_t kKeyAt = 56, kPayloadBytesAt = 88, kPayloadChecksumAt = 96, kHeaderChecksumAt = 104;

template <typename T>
void put(std::string& bytes, std::size_t at, T v) {
  std::memcpy(bytes.data() + at, &v, sizeof v);
}
template <typename T>
T get(const std::string& bytes, std::size_t at) {
  T v;
  std::memcpy(&v, bytes.data() + at, sizeof v);
  return v;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace surgsim;
  using compliance::kTensorCacheHeaderBytes;
  std::string bytes(fuzz::as_text(data, size));
  compliance::TensorCacheKey key;
  if (bytes.size() >= kTensorCacheHeaderBytes) {
    const std::size_t payload = bytes.size() - kTensorCacheHeaderBytes;
    put<std::uint64_t>(bytes, kPayloadBytesAt, payload);
    put(bytes, kPayloadChecksumAt, compliance::tensor_cache_checksum(bytes.data() + kTensorCacheHeaderBytes, payload));
    put(bytes, kHeaderChecksumAt, compliance::tensor_cache_checksum(bytes.data(), kHeaderChecksumAt));
    key.mesh = get<std::uint64_t>(bytes, kKeyAt);
    key.material = get<std::uint64_t>(bytes, kKeyAt + 8);
    key.fixed = get<std::uint64_t>(bytes, kKeyAt + 16);
    key.settings = get<std::uint64_t>(bytes, kKeyAt + 24);
  }
  const std::string path = fuzz::write_input("tensors.bin", bytes);
  compliance::Tensors tensors;
  const compliance::CacheLoad load = compliance::load_tensor_cache(path, key, tensors);
  if (load.status == compliance::CacheStatus::kOk) {
    const Eigen::Index cols = 3 * static_cast<Eigen::Index>(tensors.column_count());
    for (const auto& b : tensors.blocks) {
      const Eigen::Index rows = 3 * static_cast<Eigen::Index>(b.row_count());
      if (rows > 0 && cols > 0) {
        (void)b.at(0, 0);
        (void)b.at(rows - 1, cols - 1);
      }
    }
    // The same file for one named block only (the others are read and dropped), as the visual node loads it.
    if (!tensors.blocks.empty()) {
      compliance::Tensors one;
      (void)compliance::load_tensor_cache(path, key, one, {tensors.blocks.front().name});
    }
  }
  return 0;
}
