// Tensor cache file (docs/DESIGN.md, section 'Files'): a binary file holding precomputed Tensors, with a header (magic,
// version, precision, counts), the hashes of everything the tensors depend on (mesh, material, fixed set, solver
// settings) and a payload checksum. A stale or corrupt file is detected and reported, never used.
//
// Layout (little-endian): header = magic "SURGTNSR", u32 version, u32 byte-order tag, u32 precision (4|8),
// u32 method (0 direct, 1 cg), f64 cg tolerance, i64 nodes, i64 contact nodes, i64 blocks, u64 mesh / material /
// fixed / settings hashes, u64 payload bytes, u64 payload checksum, u64 header checksum. Payload = i32 contact nodes
// [S], u8 fixed masks [#V], then per block: u32 name length, name, i64 rows R, i32 row nodes [R], u32 layout (0: the
// 3R x 3S matrix column-major; 1: symmetric, R = S, the 9 R (R + 1) / 2 packed entries of TensorBlock::packed), in
// the stored precision. Version 2 (version 1 had no layout field): a file of another version is stale,
// never parsed.
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "compliance/precompute.h"

namespace surgsim::compliance {

/// What a cache must match to be used.
struct TensorCacheKey {
  std::uint64_t mesh = 0;      // mesh_hash(mesh)
  std::uint64_t material = 0;  // material_hash(material)
  std::uint64_t fixed = 0;     // FixedSet::hash()
  std::uint64_t settings = 0;  // precompute_settings_hash(...)
  /// One hash of all four (e.g. the tensor hash in SceneInfo).
  std::uint64_t combined() const;
};

std::uint64_t material_hash(const fem::Material& material);
/// Hash of the contact nodes, row sets (names and nodes), precision, symmetric storage, method and CG tolerance /
/// iteration limit (not the threads or block size: the same tensors to rounding).
std::uint64_t precompute_settings_hash(const std::vector<int>& contact_nodes, const std::vector<RowSet>& rows,
                                       const PrecomputeOptions& options);
TensorCacheKey tensor_cache_key(const mesh::TetMesh& mesh, const fem::Material& material, const fem::FixedSet& fixed,
                                const std::vector<int>& contact_nodes, const std::vector<RowSet>& rows,
                                const PrecomputeOptions& options);

enum class CacheStatus {
  kOk,       // loaded; `out` holds the tensors
  kMissing,  // no file at that path
  kStale,    // a well-formed file made from other inputs (detail: which hash differs) or by another format version
  kCorrupt,  // not a cache, truncated, or a checksum mismatch (detail: why)
};
const char* to_string(CacheStatus status);

/// Bytes of the header (the layout above), the payload following.
inline constexpr std::size_t kTensorCacheHeaderBytes = 112;
/// The checksum the header and the payload carry (64-bit, over 8-byte words): for a test or a fuzz target that makes
/// or alters a file by hand and seals it as save_tensor_cache does.
std::uint64_t tensor_cache_checksum(const void* data, std::size_t bytes);

struct CacheLoad {
  CacheStatus status = CacheStatus::kMissing;
  std::string detail;  // human-readable reason when not kOk
};

/// Writes atomically (temporary file, then rename). Throws surgsim::core::Error on an I/O failure.
void save_tensor_cache(const std::string& path, const Tensors& tensors, const TensorCacheKey& key);

/// Loads a cache if it matches `expected`. `blocks`: names of the blocks to keep (empty = all; others are read for
/// the checksum and dropped, so a visual node need not hold the haptic rows); a requested block missing from the file
/// makes it stale. On anything but kOk, `out` is left empty. Never throws for a bad file: every count in the header
/// and the payload is checked against the bytes the file holds before anything is sized from it (no vector takes more
/// than four times the file), so a damaged or forged count is reported as kCorrupt instead of std::bad_alloc.
CacheLoad load_tensor_cache(const std::string& path, const TensorCacheKey& expected, Tensors& out,
                            const std::vector<std::string>& blocks = {});

struct CacheOutcome {
  CacheLoad load;          // what loading found
  bool rebuilt = false;    // tensors were precomputed
  bool saved = false;      // the rebuilt tensors were written
  std::string save_error;  // why writing failed (the tensors are still returned)
};

/// Loads `path` if valid for these inputs; otherwise precomputes (reporting through options.progress) and rewrites
/// it. An empty path only precomputes. Throws what precompute_tensors throws.
Tensors load_or_build_tensors(const std::string& path, const fem::ElasticModel& model,
                              const std::vector<int>& contact_nodes, const std::vector<RowSet>& rows,
                              const PrecomputeOptions& options, CacheOutcome* outcome = nullptr,
                              PrecomputeReport* report = nullptr);

}  // namespace surgsim::compliance
