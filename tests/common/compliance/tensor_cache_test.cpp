#include "compliance/tensor_cache.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>

#include "liver/liver_setup.h"

#include "support/alloc_counter.h"
#include "support/liver_test_util.h"

using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::liver;

namespace surgsim {
namespace {

namespace fs = std::filesystem;

// Header fields (the layout in tensor_cache.h): the counts of nodes, contact nodes and blocks, and the header checksum
// over every byte before it.
constexpr std::size_t kNodesAt = 32, kContactsAt = 40, kBlocksAt = 48, kHeaderChecksumAt = 104;
static_assert(kHeaderChecksumAt + 8 == kTensorCacheHeaderBytes, "the header ends with its checksum");

// A forged header, as a crafted file would have it: the counts replaced and the header checksum made to match them.
void forge_counts(std::vector<char>& bytes, std::int64_t nodes, std::int64_t contacts, std::int64_t blocks) {
  std::memcpy(bytes.data() + kNodesAt, &nodes, 8);
  std::memcpy(bytes.data() + kContactsAt, &contacts, 8);
  std::memcpy(bytes.data() + kBlocksAt, &blocks, 8);
  const std::uint64_t digest = tensor_cache_checksum(bytes.data(), kHeaderChecksumAt);
  std::memcpy(bytes.data() + kHeaderChecksumAt, &digest, 8);
}

// No single request above this while a forged file is read: the ceiling refuses it (std::bad_alloc) instead of taking
// the memory, so a reader that sized a vector from a forged count fails the test at once, on any machine.
constexpr std::size_t kReadCeiling = std::size_t{16} << 20;

class TensorCacheTest : public ::testing::Test {
 protected:
  void SetUp() override {
    organ_ = test::box_organ(4, 3, 2);
    contacts_ = contactable_nodes(organ_->mesh, organ_->fixed);
    rows_ = standard_row_sets(organ_->mesh, contacts_);
    tensors_ = precompute_tensors(organ_->model, contacts_, rows_, options_);
    key_ = tensor_cache_key(organ_->mesh, organ_->material, organ_->fixed, contacts_, rows_, options_);
    dir_ = fs::temp_directory_path() /
           ("surgsim_tensor_cache_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    path_ = (dir_ / "liver.tensors").string();
  }
  void TearDown() override { fs::remove_all(dir_); }

  // The tensor setup of a scene "box.yaml" fixing the box's bottom, its cache in dir_.
  LiverTensorSetup scene_setup() const {
    FixedRegion bottom;
    bottom.has_plane = true;
    bottom.plane_point = Eigen::Vector3d(0, 0, 1e-9);
    bottom.plane_normal = -Eigen::Vector3d::UnitZ();
    return liver_tensor_setup(organ_->material, bottom, organ_->mesh, dir_.string(), "box.yaml");
  }

  std::vector<char> read_bytes() const {
    std::ifstream f(path_, std::ios::binary);
    return std::vector<char>(std::istreambuf_iterator<char>(f), {});
  }
  void write_bytes(const std::vector<char>& b) const {
    std::ofstream f(path_, std::ios::binary | std::ios::trunc);
    f.write(b.data(), static_cast<std::streamsize>(b.size()));
  }

  std::unique_ptr<test::Organ> organ_;
  std::vector<int> contacts_;
  std::vector<RowSet> rows_;
  PrecomputeOptions options_;
  Tensors tensors_;
  TensorCacheKey key_;
  fs::path dir_;
  std::string path_;
};

TEST_F(TensorCacheTest, RoundTripIsBitExact) {
  save_tensor_cache(path_, tensors_, key_);
  Tensors back;
  const CacheLoad r = load_tensor_cache(path_, key_, back);
  ASSERT_EQ(r.status, CacheStatus::kOk) << r.detail;
  EXPECT_EQ(back.node_count, tensors_.node_count);
  EXPECT_EQ(back.contact_nodes, tensors_.contact_nodes);
  EXPECT_EQ(back.column_of_node, tensors_.column_of_node);
  EXPECT_EQ(back.fixed_mask, tensors_.fixed_mask);
  ASSERT_EQ(back.blocks.size(), 2u);
  for (std::size_t k = 0; k < 2; ++k) {
    EXPECT_EQ(back.blocks[k].name, tensors_.blocks[k].name);
    EXPECT_EQ(back.blocks[k].row_nodes, tensors_.blocks[k].row_nodes);
    EXPECT_EQ(back.blocks[k].row_of_node, tensors_.blocks[k].row_of_node);
    EXPECT_TRUE(back.blocks[k].g == tensors_.blocks[k].g);
  }
  // Saving the same tensors again gives the same bytes.
  const auto first = read_bytes();
  save_tensor_cache(path_, tensors_, key_);
  EXPECT_EQ(read_bytes(), first);
}

TEST_F(TensorCacheTest, FloatRoundTripAndBlockSelection) {
  PrecomputeOptions opts;
  opts.precision = Precision::kFloat;
  const Tensors t = precompute_tensors(organ_->model, contacts_, rows_, opts);
  const TensorCacheKey key = tensor_cache_key(organ_->mesh, organ_->material, organ_->fixed, contacts_, rows_, opts);
  EXPECT_NE(key.settings, key_.settings);  // precision is part of the settings
  save_tensor_cache(path_, t, key);
  Tensors back;
  ASSERT_EQ(load_tensor_cache(path_, key, back, {"visual"}).status, CacheStatus::kOk);
  ASSERT_EQ(back.blocks.size(), 1u);
  EXPECT_EQ(back.precision, Precision::kFloat);
  EXPECT_TRUE(back.blocks[0].g_float == t.find("visual")->g_float);
  const CacheLoad missing_block = load_tensor_cache(path_, key, back, {"surgeon"});
  EXPECT_EQ(missing_block.status, CacheStatus::kStale);
  EXPECT_TRUE(back.blocks.empty());
}

TEST_F(TensorCacheTest, MissingFile) {
  Tensors back;
  EXPECT_EQ(load_tensor_cache(path_, key_, back).status, CacheStatus::kMissing);
}

TEST_F(TensorCacheTest, ChangedYoungModulusIsStale) {
  save_tensor_cache(path_, tensors_, key_);
  Material stiffer = organ_->material;
  stiffer.young_modulus *= 1.01;
  const TensorCacheKey key = tensor_cache_key(organ_->mesh, stiffer, organ_->fixed, contacts_, rows_, options_);
  Tensors back;
  const CacheLoad r = load_tensor_cache(path_, key, back);
  EXPECT_EQ(r.status, CacheStatus::kStale);
  EXPECT_NE(r.detail.find("material hash differs"), std::string::npos) << r.detail;
  EXPECT_EQ(r.detail.find("mesh"), std::string::npos) << r.detail;
  EXPECT_TRUE(back.blocks.empty());
}

TEST_F(TensorCacheTest, OtherMeshFixedSetOrSettingsAreStale) {
  save_tensor_cache(path_, tensors_, key_);
  Tensors back;
  TensorCacheKey k = key_;
  k.mesh ^= 1;
  EXPECT_NE(load_tensor_cache(path_, k, back).detail.find("mesh hash differs"), std::string::npos);
  k = key_;
  k.fixed ^= 1;
  EXPECT_NE(load_tensor_cache(path_, k, back).detail.find("fixed set hash differs"), std::string::npos);
  PrecomputeOptions cg = options_;
  cg.method = SolveMethod::kCg;
  k = tensor_cache_key(organ_->mesh, organ_->material, organ_->fixed, contacts_, rows_, cg);
  const CacheLoad r = load_tensor_cache(path_, k, back);
  EXPECT_EQ(r.status, CacheStatus::kStale);
  EXPECT_NE(r.detail.find("solver settings hash differs"), std::string::npos) << r.detail;
}

TEST_F(TensorCacheTest, FlippedByteIsCorrupt) {
  save_tensor_cache(path_, tensors_, key_);
  const auto good = read_bytes();
  // One bit in the payload (deep inside the matrix), in the header's counts, and in the magic.
  for (std::size_t at : {good.size() - 12345, std::size_t{40}, std::size_t{2}}) {
    auto bad = good;
    bad[at] = static_cast<char>(bad[at] ^ 0x10);
    write_bytes(bad);
    Tensors back;
    const CacheLoad r = load_tensor_cache(path_, key_, back);
    EXPECT_EQ(r.status, CacheStatus::kCorrupt) << at << ": " << r.detail;
    EXPECT_TRUE(back.blocks.empty());
  }
  auto truncated = good;
  truncated.resize(good.size() - 8);
  write_bytes(truncated);
  Tensors back;
  const CacheLoad r = load_tensor_cache(path_, key_, back);
  EXPECT_EQ(r.status, CacheStatus::kCorrupt);
  EXPECT_NE(r.detail.find("truncated"), std::string::npos) << r.detail;
  write_bytes(std::vector<char>{'h', 'e', 'l', 'l', 'o'});
  EXPECT_EQ(load_tensor_cache(path_, key_, back).status, CacheStatus::kCorrupt);
}

TEST_F(TensorCacheTest, LoadOrBuildRebuildsStaleAndCorruptFiles) {
  CacheOutcome o;
  Tensors t = load_or_build_tensors(path_, organ_->model, contacts_, rows_, options_, &o);
  EXPECT_EQ(o.load.status, CacheStatus::kMissing);
  EXPECT_TRUE(o.rebuilt);
  EXPECT_TRUE(o.saved) << o.save_error;
  t = load_or_build_tensors(path_, organ_->model, contacts_, rows_, options_, &o);
  EXPECT_EQ(o.load.status, CacheStatus::kOk);
  EXPECT_FALSE(o.rebuilt);
  EXPECT_TRUE(t.find("haptic")->g == tensors_.find("haptic")->g);
  auto bytes = read_bytes();
  bytes[bytes.size() / 2] = static_cast<char>(bytes[bytes.size() / 2] ^ 1);
  write_bytes(bytes);
  t = load_or_build_tensors(path_, organ_->model, contacts_, rows_, options_, &o);
  EXPECT_EQ(o.load.status, CacheStatus::kCorrupt);
  EXPECT_TRUE(o.rebuilt);
  EXPECT_TRUE(t.find("haptic")->g == tensors_.find("haptic")->g);
  Tensors back;
  EXPECT_EQ(load_tensor_cache(path_, key_, back).status, CacheStatus::kOk);
}

// The packed symmetric haptic half in float, written and read back bit for bit.
TEST_F(TensorCacheTest, SymmetricFloatRoundTrip) {
  PrecomputeOptions opts;
  opts.precision = Precision::kFloat;
  opts.symmetric_blocks = {"haptic"};
  const auto rows = standard_row_sets(organ_->mesh, organ_->fixed, contacts_);
  const Tensors t = precompute_tensors(organ_->model, contacts_, rows, opts);
  const TensorCacheKey key = tensor_cache_key(organ_->mesh, organ_->material, organ_->fixed, contacts_, rows, opts);
  PrecomputeOptions dense = opts;
  dense.symmetric_blocks.clear();
  EXPECT_NE(key.settings,
            tensor_cache_key(organ_->mesh, organ_->material, organ_->fixed, contacts_, rows, dense).settings);
  save_tensor_cache(path_, t, key);
  Tensors back;
  ASSERT_EQ(load_tensor_cache(path_, key, back, {"haptic"}).status, CacheStatus::kOk);
  ASSERT_EQ(back.blocks.size(), 1u);
  EXPECT_TRUE(back.blocks[0].symmetric);
  EXPECT_EQ(back.blocks[0].packed_float, t.find("haptic")->packed_float);
  EXPECT_EQ(back.blocks[0].block3(2, 5), t.find("haptic")->block3(2, 5));
  ASSERT_EQ(load_tensor_cache(path_, key, back, {"visual"}).status, CacheStatus::kOk);
  EXPECT_FALSE(back.blocks[0].symmetric);
  EXPECT_TRUE(back.blocks[0].g_float == t.find("visual")->g_float);
}

// A file of format version 1 (dense blocks, no layout field) is stale with a message saying what to do, never parsed
// as version 2; load_or_build_tensors rewrites it.
TEST_F(TensorCacheTest, OlderFormatVersionIsRefusedAndRebuilt) {
  save_tensor_cache(path_, tensors_, key_);
  auto bytes = read_bytes();
  const std::uint32_t v1 = 1;
  std::memcpy(bytes.data() + 8, &v1, sizeof v1);  // the version follows the 8-byte magic
  write_bytes(bytes);
  Tensors back;
  const CacheLoad r = load_tensor_cache(path_, key_, back);
  EXPECT_EQ(r.status, CacheStatus::kStale);
  EXPECT_NE(r.detail.find("format version 1"), std::string::npos) << r.detail;
  EXPECT_NE(r.detail.find("reads version 2"), std::string::npos) << r.detail;
  EXPECT_NE(r.detail.find("recompute"), std::string::npos) << r.detail;
  EXPECT_TRUE(back.blocks.empty());
  CacheOutcome o;
  const Tensors t = load_or_build_tensors(path_, organ_->model, contacts_, rows_, options_, &o);
  EXPECT_EQ(o.load.status, CacheStatus::kStale);
  EXPECT_TRUE(o.rebuilt);
  EXPECT_TRUE(o.saved) << o.save_error;
  EXPECT_EQ(load_tensor_cache(path_, key_, back).status, CacheStatus::kOk);
}

// Counts in a forged header (its checksum made to match) are checked against the payload, with overflow-safe
// arithmetic, before anything is sized from them: a clear 'corrupt' naming the counts, never std::bad_alloc and never
// a request larger than the file (the reader sized 4 GiB of node tables from the first two before the check).
TEST_F(TensorCacheTest, ForgedHeaderCountsAreRefusedBeforeAnyAllocation) {
  save_tensor_cache(path_, tensors_, key_);
  const auto good = read_bytes();
  const std::int64_t nodes = tensors_.node_count, contacts = tensors_.column_count();
  const std::int64_t file_bytes = static_cast<std::int64_t>(good.size());
  struct Forged {
    const char* what;
    std::int64_t nodes, contacts, blocks;
  };
  const Forged forged[] = {
      {"nodes at the format's limit (4 GiB of node tables)", std::int64_t{1} << 30, contacts, 2},
      {"nodes and contacts at the limit (a 4 GiB contact list)", std::int64_t{1} << 30, std::int64_t{1} << 30, 2},
      {"more nodes than the file has bytes", file_bytes, contacts, 2},
      {"more contacts than the file can hold", nodes + file_bytes / 4, nodes + file_bytes / 4, 2},
      {"more blocks than the format allows", nodes, contacts, 1025},
      {"counts whose byte sizes overflow 64 bits", std::int64_t{1} << 62, (std::int64_t{1} << 62) + 1, 2},
      {"negative counts", -1, contacts, 2},
  };
  for (const Forged& f : forged) {
    auto bad = good;
    forge_counts(bad, f.nodes, f.contacts, f.blocks);
    write_bytes(bad);
    Tensors back;
    CacheLoad r;
    std::size_t largest = 0;
    {
      test::AllocationCeiling ceiling(kReadCeiling);
      EXPECT_NO_THROW(r = load_tensor_cache(path_, key_, back)) << f.what;
      largest = ceiling.largest();
    }
    EXPECT_EQ(r.status, CacheStatus::kCorrupt) << f.what << ": " << r.detail;
    EXPECT_NE(r.detail.find("count"), std::string::npos) << f.what << ": " << r.detail;
    EXPECT_LE(largest, good.size()) << f.what << ": the largest request, bytes";
    EXPECT_TRUE(back.blocks.empty()) << f.what;
  }
  // The counts it was written with still read.
  auto same = good;
  forge_counts(same, nodes, contacts, static_cast<std::int64_t>(tensors_.blocks.size()));
  EXPECT_EQ(same, good);
}

// A scene's cache with a forged header: refused without the memory its counts ask for, named in the log and rebuilt.
TEST_F(TensorCacheTest, ForgedSceneCacheIsNamedAndRebuilt) {
  const LiverTensorSetup setup = scene_setup();
  const Tensors first = load_liver_tensors(setup, organ_->mesh, organ_->material, {"haptic"}, nullptr);
  path_ = setup.cache_path;
  auto bytes = read_bytes();
  forge_counts(bytes, std::int64_t{1} << 30, std::int64_t{1} << 30, 2);
  write_bytes(bytes);
  std::ostringstream log;
  CacheOutcome o;
  Tensors t;
  {
    test::AllocationCeiling ceiling(kReadCeiling);
    EXPECT_NO_THROW(t = load_liver_tensors(setup, organ_->mesh, organ_->material, {"haptic"}, &log, &o, "box.yaml"));
  }
  EXPECT_EQ(o.load.status, CacheStatus::kCorrupt) << o.load.detail;
  EXPECT_TRUE(o.rebuilt);
  EXPECT_NE(log.str().find(setup.cache_path), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("1073741824 nodes"), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("rebuilding it"), std::string::npos) << log.str();
  ASSERT_NE(t.find("haptic"), nullptr);
  EXPECT_EQ(t.find("haptic")->packed, first.find("haptic")->packed);
}

// A scene's corrupt cache: the log names the file, what is wrong and what happens (rebuilt in place).
TEST_F(TensorCacheTest, CorruptSceneCacheIsNamedAndRebuilt) {
  const LiverTensorSetup setup = scene_setup();
  EXPECT_EQ(setup.options.symmetric_blocks, std::vector<std::string>{"haptic"});
  EXPECT_EQ(setup.options.precision, Precision::kDouble);  // a few MiB: double
  Tensors first = load_liver_tensors(setup, organ_->mesh, organ_->material, {"haptic"}, nullptr);
  EXPECT_TRUE(first.find("haptic")->symmetric);
  std::ofstream(setup.cache_path, std::ios::binary | std::ios::trunc) << "not a cache";
  std::ostringstream log;
  CacheOutcome o;
  const Tensors t = load_liver_tensors(setup, organ_->mesh, organ_->material, {"haptic"}, &log, &o, "box.yaml");
  EXPECT_EQ(o.load.status, CacheStatus::kCorrupt);
  EXPECT_TRUE(o.rebuilt);
  EXPECT_NE(log.str().find(setup.cache_path), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("corrupt"), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("rebuilding it"), std::string::npos) << log.str();
  EXPECT_EQ(t.find("haptic")->packed, first.find("haptic")->packed);
}

}  // namespace
}  // namespace surgsim
