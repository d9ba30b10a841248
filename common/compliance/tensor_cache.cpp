#include "compliance/tensor_cache.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/error.h"
#include "core/hash.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;

namespace surgsim::compliance {
namespace {

constexpr char kMagic[8] = {'S', 'U', 'R', 'G', 'T', 'N', 'S', 'R'};
// 1: dense blocks only. 2: a u32 layout per block (0 dense 3R x 3S, 1 symmetric packed half).
constexpr std::uint32_t kVersion = 2;
constexpr std::uint32_t kByteOrder = 0x01020304u;
constexpr std::size_t kHeaderBytes = kTensorCacheHeaderBytes;
static_assert(kHeaderBytes == 8 + 4 * 4 + 8 + 3 * 8 + 4 * 8 + 3 * 8, "the header's fields");

// Streaming 64-bit checksum over 8-byte words (FNV-1a style mixing per word; 8x faster than per byte).
class Checksum {
 public:
  void update(const void* data, std::size_t n) {
    const auto* p = static_cast<const unsigned char*>(data);
    while (n > 0 && pending_ > 0) {
      buf_[pending_++] = *p++;
      --n;
      if (pending_ == 8) flush();
    }
    while (n >= 8) {
      std::uint64_t w;
      std::memcpy(&w, p, 8);
      mix(w);
      p += 8;
      n -= 8;
    }
    while (n > 0) {
      buf_[pending_++] = *p++;
      --n;
    }
  }
  std::uint64_t digest() const {
    Checksum c = *this;
    if (c.pending_ > 0) {
      std::memset(c.buf_.data() + c.pending_, 0, 8 - static_cast<std::size_t>(c.pending_));
      std::uint64_t w;
      std::memcpy(&w, c.buf_.data(), 8);
      c.mix(w ^ (static_cast<std::uint64_t>(c.pending_) << 56));
    }
    return c.h_ ^ (c.h_ >> 29);
  }

 private:
  void flush() {
    std::uint64_t w;
    std::memcpy(&w, buf_.data(), 8);
    mix(w);
    pending_ = 0;
  }
  void mix(std::uint64_t w) {
    h_ ^= w;
    h_ *= 1099511628211ull;
    h_ ^= h_ >> 32;
  }
  std::uint64_t h_ = 1469598103934665603ull;
  std::array<unsigned char, 8> buf_{};
  int pending_ = 0;
};

// Little byte writer (the header is assembled field by field: no struct padding in the file).
class Bytes {
 public:
  template <typename T>
  void put(const T& v) {
    const auto* p = reinterpret_cast<const unsigned char*>(&v);
    data_.insert(data_.end(), p, p + sizeof(T));
  }
  void put_raw(const void* p, std::size_t n) {
    const auto* c = static_cast<const unsigned char*>(p);
    data_.insert(data_.end(), c, c + n);
  }
  const std::vector<unsigned char>& data() const { return data_; }

 private:
  std::vector<unsigned char> data_;
};

// Sequential reader over the header bytes.
class HeaderReader {
 public:
  explicit HeaderReader(const unsigned char* p) : p_(p) {}
  template <typename T>
  T get() {
    T v;
    std::memcpy(&v, p_, sizeof(T));
    p_ += sizeof(T);
    return v;
  }

 private:
  const unsigned char* p_;
};

struct Header {
  std::uint32_t version = 0, byte_order = 0, precision = 0, method = 0;
  double cg_tolerance = 0;
  std::int64_t nodes = 0, contacts = 0, blocks = 0;
  TensorCacheKey key;
  std::uint64_t payload_bytes = 0, payload_checksum = 0, header_checksum = 0;
};

std::vector<unsigned char> encode_header(const Header& h) {
  Bytes b;
  b.put_raw(kMagic, 8);
  b.put(h.version);
  b.put(h.byte_order);
  b.put(h.precision);
  b.put(h.method);
  b.put(h.cg_tolerance);
  b.put(h.nodes);
  b.put(h.contacts);
  b.put(h.blocks);
  b.put(h.key.mesh);
  b.put(h.key.material);
  b.put(h.key.fixed);
  b.put(h.key.settings);
  b.put(h.payload_bytes);
  b.put(h.payload_checksum);
  Checksum c;
  c.update(b.data().data(), b.data().size());
  b.put(c.digest());
  return b.data();
}

std::string hex(std::uint64_t v) {
  char buf[24];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

// Payload writer: streams to the file while checksumming.
class PayloadWriter {
 public:
  explicit PayloadWriter(std::ofstream& f) : f_(f) {}
  void write(const void* p, std::size_t n) {
    if (n == 0) return;
    f_.write(static_cast<const char*>(p), static_cast<std::streamsize>(n));
    sum_.update(p, n);
    bytes_ += n;
  }
  template <typename T>
  void put(const T& v) {
    write(&v, sizeof(T));
  }
  std::uint64_t bytes() const { return bytes_; }
  std::uint64_t checksum() const { return sum_.digest(); }

 private:
  std::ofstream& f_;
  Checksum sum_;
  std::uint64_t bytes_ = 0;
};

// Payload reader: bounded by the declared payload size; every read is checksummed.
class PayloadReader {
 public:
  PayloadReader(std::ifstream& f, std::uint64_t limit) : f_(f), left_(limit) {}
  bool read(void* p, std::size_t n) {
    if (n > left_) return false;
    if (n == 0) return true;
    f_.read(static_cast<char*>(p), static_cast<std::streamsize>(n));
    if (!f_) return false;
    sum_.update(p, n);
    left_ -= n;
    return true;
  }
  template <typename T>
  bool get(T& v) {
    return read(&v, sizeof(T));
  }
  bool skip(std::uint64_t n) {
    std::vector<unsigned char> buf(static_cast<std::size_t>(std::min<std::uint64_t>(n, 1 << 20)));
    while (n > 0) {
      const std::size_t k = static_cast<std::size_t>(std::min<std::uint64_t>(n, buf.size()));
      if (!read(buf.data(), k)) return false;
      n -= k;
    }
    return true;
  }
  std::uint64_t left() const { return left_; }
  std::uint64_t checksum() const { return sum_.digest(); }

 private:
  std::ifstream& f_;
  Checksum sum_;
  std::uint64_t left_;
};

CacheLoad result(CacheStatus s, const std::string& detail) { return CacheLoad{s, detail}; }

// Limits of the header's counts, and the bytes a block holds before its row nodes (u32 name length, i64 row count,
// u32 layout).
constexpr std::int64_t kMaxNodes = std::int64_t{1} << 30;
constexpr std::int64_t kMaxBlocks = 1024;
constexpr std::uint64_t kBlockFixedBytes = 4 + 8 + 4;

// Whether `count` items of `size` bytes fit in `left` bytes: a count read from the file is checked against the bytes
// that remain before anything is sized from it (a division, so no product that could wrap).
bool fits(std::uint64_t count, std::uint64_t size, std::uint64_t left) { return count <= left / size; }

// a * b + c, or false when it passes 2^64 (forged counts must not wrap to a small size).
bool mul_add(std::uint64_t a, std::uint64_t b, std::uint64_t c, std::uint64_t& out) {
  return !__builtin_mul_overflow(a, b, &out) && !__builtin_add_overflow(out, c, &out);
}

// The least payload the header's counts imply: the contact list, a fixed-mask byte per node and each block's fixed
// fields. False when that passes 2^64. The counts are non-negative here.
bool least_payload(const Header& h, std::uint64_t& out) {
  std::uint64_t blocks = 0, contacts = 0;
  return mul_add(static_cast<std::uint64_t>(h.blocks), kBlockFixedBytes, 0, blocks) &&
         mul_add(static_cast<std::uint64_t>(h.contacts), sizeof(std::int32_t), blocks, contacts) &&
         mul_add(static_cast<std::uint64_t>(h.nodes), 1, contacts, out);
}

std::string counts_text(const Header& h) {
  return std::to_string(h.nodes) + " nodes, " + std::to_string(h.contacts) + " contact nodes, " +
         std::to_string(h.blocks) + " blocks";
}

}  // namespace

std::uint64_t TensorCacheKey::combined() const {
  Hasher h;
  h.value(mesh).value(material).value(fixed).value(settings);
  return h.digest();
}

std::uint64_t material_hash(const Material& material) {
  Hasher h;
  h.str("Material/1").value(material.young_modulus).value(material.poisson_ratio);
  // Regions only when there are some, so a homogeneous organ keeps its hash (and its caches). Each region's material
  // and selectors, and the frame they are written in (it moves them over the mesh); not the name, which changes no
  // element.
  if (!material.regions.empty()) {
    h.str("MaterialRegions/1").value<std::uint64_t>(material.regions.size());
    const auto num = [&h](double v) { h.value(v == 0.0 ? 0.0 : v); };  // -0 and 0 select the same elements
    const auto vec = [&num](const Eigen::Vector3d& v) { num(v.x()), num(v.y()), num(v.z()); };
    for (const MaterialRegion& r : material.regions) {
      num(r.young_modulus), num(r.poisson_ratio);
      h.value<std::uint64_t>(r.boxes.size());
      for (const auto& b : r.boxes) vec(b.first), vec(b.second);
      h.value<std::uint64_t>(r.ellipsoids.size());
      for (const Ellipsoid& e : r.ellipsoids) vec(e.center), vec(e.radii);
    }
    for (int i = 0; i < 9; ++i) num(material.frame.rotation(i / 3, i % 3));
    vec(material.frame.translation);
  }
  return h.digest();
}

std::uint64_t precompute_settings_hash(const std::vector<int>& contact_nodes, const std::vector<RowSet>& rows,
                                       const PrecomputeOptions& options) {
  Hasher h;
  h.str("PrecomputeSettings/1");
  std::vector<int> contacts = contact_nodes;
  std::sort(contacts.begin(), contacts.end());
  h.value<std::uint64_t>(contacts.size());
  if (!contacts.empty()) h.bytes(contacts.data(), contacts.size() * sizeof(int));
  h.value<std::uint64_t>(rows.size());
  for (const auto& r : rows) {
    h.str(r.name).value<std::uint64_t>(r.nodes.size());
    if (!r.nodes.empty()) h.bytes(r.nodes.data(), r.nodes.size() * sizeof(int));
  }
  h.value(static_cast<std::uint8_t>(options.precision));
  h.value(static_cast<std::uint8_t>(options.method));
  for (const auto& name : options.symmetric_blocks) h.str("symmetric").str(name);
  if (options.method == SolveMethod::kCg) h.value(options.cg_tolerance).value(options.cg_max_iterations);
  return h.digest();
}

TensorCacheKey tensor_cache_key(const TetMesh& mesh, const Material& material, const FixedSet& fixed,
                                const std::vector<int>& contact_nodes, const std::vector<RowSet>& rows,
                                const PrecomputeOptions& options) {
  TensorCacheKey k;
  k.mesh = mesh_hash(mesh);
  k.material = material_hash(material);
  k.fixed = fixed.hash();
  k.settings = precompute_settings_hash(contact_nodes, rows, options);
  return k;
}

std::uint64_t tensor_cache_checksum(const void* data, std::size_t bytes) {
  Checksum c;
  c.update(data, bytes);
  return c.digest();
}

const char* to_string(CacheStatus status) {
  switch (status) {
    case CacheStatus::kOk: return "ok";
    case CacheStatus::kMissing: return "missing";
    case CacheStatus::kStale: return "stale";
    case CacheStatus::kCorrupt: return "corrupt";
  }
  return "?";
}

void save_tensor_cache(const std::string& path, const Tensors& tensors, const TensorCacheKey& key) {
  const std::string tmp = path + ".tmp." + std::to_string(static_cast<long>(::getpid()));
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (!f) throw_error("tensor cache: cannot write ", tmp, " (", std::strerror(errno), ")");
    Header h;
    h.version = kVersion;
    h.byte_order = kByteOrder;
    h.precision = static_cast<std::uint32_t>(tensors.precision);
    h.method = tensors.method == SolveMethod::kDirect ? 0 : 1;
    h.cg_tolerance = tensors.cg_tolerance;
    h.nodes = tensors.node_count;
    h.contacts = tensors.column_count();
    h.blocks = static_cast<std::int64_t>(tensors.blocks.size());
    h.key = key;
    // Placeholder header; rewritten once the payload size and checksum are known.
    const auto placeholder = encode_header(h);
    f.write(reinterpret_cast<const char*>(placeholder.data()), static_cast<std::streamsize>(placeholder.size()));

    PayloadWriter w(f);
    for (int c : tensors.contact_nodes) w.put<std::int32_t>(c);
    w.write(tensors.fixed_mask.data(), tensors.fixed_mask.size());
    for (const auto& b : tensors.blocks) {
      w.put<std::uint32_t>(static_cast<std::uint32_t>(b.name.size()));
      w.write(b.name.data(), b.name.size());
      w.put<std::int64_t>(b.row_count());
      for (int r : b.row_nodes) w.put<std::int32_t>(r);
      w.put<std::uint32_t>(b.symmetric ? 1u : 0u);
      const auto rows = static_cast<std::size_t>(b.row_count());
      const std::size_t entries =
          b.symmetric ? 9 * rows * (rows + 1) / 2 : 9 * rows * static_cast<std::size_t>(tensors.column_count());
      if (b.symmetric) {
        const std::size_t have = tensors.precision == Precision::kDouble ? b.packed.size() : b.packed_float.size();
        if (have != entries || b.row_count() != tensors.column_count())
          throw_error("tensor cache: symmetric block '", b.name, "' has the wrong size");
        if (tensors.precision == Precision::kDouble)
          w.write(b.packed.data(), entries * sizeof(double));
        else
          w.write(b.packed_float.data(), entries * sizeof(float));
      } else if (tensors.precision == Precision::kDouble) {
        if (static_cast<std::size_t>(b.g.size()) != entries)
          throw_error("tensor cache: block '", b.name, "' has the wrong size");
        w.write(b.g.data(), entries * sizeof(double));
      } else {
        if (static_cast<std::size_t>(b.g_float.size()) != entries)
          throw_error("tensor cache: block '", b.name, "' has the wrong size");
        w.write(b.g_float.data(), entries * sizeof(float));
      }
    }
    h.payload_bytes = w.bytes();
    h.payload_checksum = w.checksum();
    const auto header = encode_header(h);
    f.seekp(0);
    f.write(reinterpret_cast<const char*>(header.data()), static_cast<std::streamsize>(header.size()));
    f.flush();
    if (!f) {
      std::remove(tmp.c_str());
      throw_error("tensor cache: writing ", tmp, " failed (disk full?)");
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    std::remove(tmp.c_str());
    throw_error("tensor cache: cannot rename ", tmp, " to ", path, " (", why, ")");
  }
}

CacheLoad load_tensor_cache(const std::string& path, const TensorCacheKey& expected, Tensors& out,
                            const std::vector<std::string>& blocks) {
  out = Tensors();
  std::ifstream f(path, std::ios::binary);
  if (!f) return result(CacheStatus::kMissing, "no file " + path);
  f.seekg(0, std::ios::end);
  const std::uint64_t file_size = static_cast<std::uint64_t>(f.tellg());
  f.seekg(0);

  // Header.
  std::array<unsigned char, kHeaderBytes> raw{};
  if (file_size < kHeaderBytes || !f.read(reinterpret_cast<char*>(raw.data()), kHeaderBytes))
    return result(CacheStatus::kCorrupt, "truncated header (" + std::to_string(file_size) + " bytes)");
  if (std::memcmp(raw.data(), kMagic, 8) != 0)
    return result(CacheStatus::kCorrupt, "not a surgsim tensor cache (bad magic)");
  HeaderReader hr(raw.data() + 8);
  Header h;
  h.version = hr.get<std::uint32_t>();
  if (h.version != kVersion)
    return result(CacheStatus::kStale, "format version " + std::to_string(h.version) + ", this build reads version " +
                                           std::to_string(kVersion) + " only (never read as another version: " +
                                           "recompute it, e.g. surgsim-precompute --force, or delete the file)");
  h.byte_order = hr.get<std::uint32_t>();
  h.precision = hr.get<std::uint32_t>();
  h.method = hr.get<std::uint32_t>();
  h.cg_tolerance = hr.get<double>();
  h.nodes = hr.get<std::int64_t>();
  h.contacts = hr.get<std::int64_t>();
  h.blocks = hr.get<std::int64_t>();
  h.key.mesh = hr.get<std::uint64_t>();
  h.key.material = hr.get<std::uint64_t>();
  h.key.fixed = hr.get<std::uint64_t>();
  h.key.settings = hr.get<std::uint64_t>();
  h.payload_bytes = hr.get<std::uint64_t>();
  h.payload_checksum = hr.get<std::uint64_t>();
  h.header_checksum = hr.get<std::uint64_t>();
  {
    Checksum c;
    c.update(raw.data(), kHeaderBytes - 8);
    if (c.digest() != h.header_checksum) return result(CacheStatus::kCorrupt, "header checksum mismatch");
  }
  if (h.byte_order != kByteOrder) return result(CacheStatus::kStale, "written on a machine with another byte order");

  // Identity.
  std::string differ;
  auto cmp = [&](const char* what, std::uint64_t file, std::uint64_t want) {
    if (file != want)
      differ += std::string(differ.empty() ? "" : "; ") + what + " hash differs (file " + hex(file) + ", expected " +
                hex(want) + ")";
  };
  cmp("mesh", h.key.mesh, expected.mesh);
  cmp("material", h.key.material, expected.material);
  cmp("fixed set", h.key.fixed, expected.fixed);
  cmp("solver settings", h.key.settings, expected.settings);
  if (!differ.empty()) return result(CacheStatus::kStale, differ);

  // Sizes.
  if (h.precision != 4 && h.precision != 8) return result(CacheStatus::kCorrupt, "bad precision field");
  if (h.method > 1) return result(CacheStatus::kCorrupt, "bad method field");
  if (h.nodes < 0 || h.nodes > kMaxNodes || h.contacts < 0 || h.contacts > h.nodes || h.blocks < 0 ||
      h.blocks > kMaxBlocks)
    return result(CacheStatus::kCorrupt, "header counts out of range (" + counts_text(h) +
                                             "; the format allows 0 <= contact nodes <= nodes <= 2^30 and at most " +
                                             std::to_string(kMaxBlocks) + " blocks)");
  if (file_size != kHeaderBytes + h.payload_bytes)
    return result(CacheStatus::kCorrupt, "file is " + std::to_string(file_size) + " bytes, header says " +
                                             std::to_string(kHeaderBytes + h.payload_bytes) +
                                             " (truncated or extended)");
  // Every vector below is sized from a count the payload has been shown to hold, so a forged header gets this
  // message, not std::bad_alloc or gigabytes of node tables.
  std::uint64_t least = 0;
  const bool counted = least_payload(h, least);
  if (!counted || least > h.payload_bytes)
    return result(CacheStatus::kCorrupt, "header counts (" + counts_text(h) + ") need at least " +
                                             (counted ? std::to_string(least) : "2^64") +
                                             " payload bytes, the file holds " + std::to_string(h.payload_bytes) +
                                             " (a damaged or forged header)");

  // Payload, checksummed while read; parsed with bounds checks.
  Tensors t;
  t.node_count = static_cast<int>(h.nodes);
  t.precision = static_cast<Precision>(h.precision);
  t.method = h.method == 0 ? SolveMethod::kDirect : SolveMethod::kCg;
  t.cg_tolerance = h.cg_tolerance;
  PayloadReader r(f, h.payload_bytes);
  const auto corrupt = [](const std::string& why) { return result(CacheStatus::kCorrupt, why); };
  t.contact_nodes.resize(static_cast<std::size_t>(h.contacts));
  if (!r.read(t.contact_nodes.data(), t.contact_nodes.size() * sizeof(int))) return corrupt("truncated contact list");
  t.column_of_node.assign(static_cast<std::size_t>(h.nodes), -1);
  for (std::size_t c = 0; c < t.contact_nodes.size(); ++c) {
    const int node = t.contact_nodes[c];
    if (node < 0 || node >= t.node_count || (c > 0 && node <= t.contact_nodes[c - 1]))
      return corrupt("bad contact node list");
    t.column_of_node[static_cast<std::size_t>(node)] = static_cast<int>(c);
  }
  t.fixed_mask.resize(static_cast<std::size_t>(h.nodes));
  if (!r.read(t.fixed_mask.data(), t.fixed_mask.size())) return corrupt("truncated fixed masks");
  const Eigen::Index cols = 3 * static_cast<Eigen::Index>(h.contacts);
  for (std::int64_t k = 0; k < h.blocks; ++k) {
    std::uint32_t name_len = 0;
    if (!r.get(name_len) || name_len > 4096 || name_len > r.left()) return corrupt("bad block name");
    TensorBlock b;
    b.name.resize(name_len);
    if (!r.read(b.name.data(), name_len)) return corrupt("truncated block name");
    std::int64_t rows = 0;
    if (!r.get(rows) || rows < 0 || rows > h.nodes || !fits(static_cast<std::uint64_t>(rows), 4, r.left()))
      return corrupt("bad row count " + std::to_string(rows) + " in block '" + b.name + "' (" +
                     std::to_string(r.left()) + " payload bytes left)");
    b.row_nodes.resize(static_cast<std::size_t>(rows));
    if (!r.read(b.row_nodes.data(), b.row_nodes.size() * sizeof(int)))
      return corrupt("truncated rows of '" + b.name + "'");
    std::uint32_t layout = 0;
    if (!r.get(layout) || layout > 1) return corrupt("bad layout of block '" + b.name + "'");
    if (layout == 1 && rows != h.contacts)
      return corrupt("symmetric block '" + b.name + "' is not contacts x contacts");
    // rows and contacts are at most 2^30, so the entries fit in 64 bits; their bytes are checked.
    const auto urows = static_cast<std::uint64_t>(rows);
    const std::uint64_t entries =
        layout == 1 ? 9ull * urows * (urows + 1) / 2 : 9ull * urows * static_cast<std::uint64_t>(h.contacts);
    std::uint64_t bytes = 0;
    if (!mul_add(entries, h.precision, 0, bytes) || bytes > r.left())
      return corrupt("block '" + b.name + "' runs past the end of the file");
    const bool keep = blocks.empty() || std::find(blocks.begin(), blocks.end(), b.name) != blocks.end();
    if (!keep) {
      if (!r.skip(bytes)) return corrupt("truncated block '" + b.name + "'");
      continue;
    }
    b.row_of_node.assign(static_cast<std::size_t>(h.nodes), -1);
    for (std::size_t i = 0; i < b.row_nodes.size(); ++i) {
      const int node = b.row_nodes[i];
      if (node < 0 || node >= t.node_count || b.row_of_node[static_cast<std::size_t>(node)] >= 0)
        return corrupt("bad row node in block '" + b.name + "'");
      b.row_of_node[static_cast<std::size_t>(node)] = static_cast<int>(i);
    }
    bool ok;
    b.symmetric = layout == 1;
    if (b.symmetric && t.precision == Precision::kDouble) {
      b.packed.resize(static_cast<std::size_t>(entries));
      ok = r.read(b.packed.data(), static_cast<std::size_t>(bytes));
    } else if (b.symmetric) {
      b.packed_float.resize(static_cast<std::size_t>(entries));
      ok = r.read(b.packed_float.data(), static_cast<std::size_t>(bytes));
    } else if (t.precision == Precision::kDouble) {
      b.g.resize(3 * rows, cols);
      ok = r.read(b.g.data(), static_cast<std::size_t>(bytes));
    } else {
      b.g_float.resize(3 * rows, cols);
      ok = r.read(b.g_float.data(), static_cast<std::size_t>(bytes));
    }
    if (!ok) return corrupt("truncated block '" + b.name + "'");
    t.blocks.push_back(std::move(b));
  }
  if (r.left() != 0) return corrupt("unexpected bytes after the last block");
  if (r.checksum() != h.payload_checksum) return corrupt("payload checksum mismatch");
  for (const auto& name : blocks)
    if (!t.find(name)) return result(CacheStatus::kStale, "the file has no block '" + name + "'");
  out = std::move(t);
  return result(CacheStatus::kOk, "");
}

Tensors load_or_build_tensors(const std::string& path, const ElasticModel& model, const std::vector<int>& contact_nodes,
                              const std::vector<RowSet>& rows, const PrecomputeOptions& options, CacheOutcome* outcome,
                              PrecomputeReport* report) {
  CacheOutcome local;
  CacheOutcome& o = outcome ? *outcome : local;
  o = CacheOutcome();
  Tensors t;
  TensorCacheKey key;
  if (!path.empty()) {
    key = tensor_cache_key(*model.mesh, model.material, model.fixed, contact_nodes, rows, options);
    o.load = load_tensor_cache(path, key, t);
    if (o.load.status == CacheStatus::kOk) {
      t.material = model.material;  // part of the key
      return t;
    }
  } else {
    o.load = result(CacheStatus::kMissing, "no cache path given");
  }
  t = precompute_tensors(model, contact_nodes, rows, options, report);
  o.rebuilt = true;
  if (!path.empty()) {
    try {
      save_tensor_cache(path, t, key);
      o.saved = true;
    } catch (const Error& e) {
      o.save_error = e.what();
    }
  }
  return t;
}

}  // namespace surgsim::compliance
