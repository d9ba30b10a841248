// The single-producer rings: the slot ring (lines from the loop to a writer thread) and the sequence-locked ring (the
// loop's records to the publisher), alone and between two real threads.
#include <gtest/gtest.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "concurrency/seqlock_ring.h"
#include "concurrency/spsc_slot_ring.h"

namespace surgsim::concurrency {
namespace {

TEST(SpscSlotRing, FullRingRefusesAClaimUntilASlotIsConsumed) {
  SpscSlotRing ring(2, 8);
  for (int i = 0; i < 2; ++i) {
    char* s = ring.claim();
    ASSERT_NE(s, nullptr);
    s[0] = static_cast<char>('a' + i);
    ring.publish(1);
  }
  EXPECT_EQ(ring.claim(), nullptr);
  EXPECT_EQ(ring.size(), 2u);
  std::string seen;
  EXPECT_EQ(ring.consume([&](const char* d, std::size_t n) { seen.append(d, n); }), 2u);
  EXPECT_EQ(seen, "ab");
  EXPECT_NE(ring.claim(), nullptr);
}

TEST(SpscSlotRing, LengthIsCappedAtTheSlotSize) {
  SpscSlotRing ring(4, 4);
  std::memcpy(ring.claim(), "abcd", 4);
  ring.publish(100);
  std::size_t got = 0;
  ring.consume([&](const char*, std::size_t n) { got = n; });
  EXPECT_EQ(got, 4u);
}

TEST(SpscSlotRing, CountersSitOnCacheLinesOfTheirOwn) {
  // The producer's and the consumer's counters must not share a cache line (false sharing at 1 kHz).
  EXPECT_GE(alignof(SpscSlotRing), 64u);
}

// Two threads: every line arrives once, whole and in order (a small ring, so the producer meets it full often).
TEST(SpscSlotRing, ConcurrentLinesArriveWholeAndInOrder) {
  SpscSlotRing ring(8, 32);
  constexpr int kLines = 200000;
  std::atomic<bool> done{false};
  std::vector<int> bad;
  int next = 0;
  std::thread consumer([&] {
    const auto take = [&](const char* d, std::size_t n) {
      const std::string line(d, n);
      if (line != "line " + std::to_string(next)) bad.push_back(next);
      ++next;
    };
    while (!done.load(std::memory_order_acquire)) ring.consume(take);
    ring.consume(take);
  });
  for (int i = 0; i < kLines; ++i) {
    char* s;
    while ((s = ring.claim()) == nullptr) std::this_thread::yield();
    const std::string line = "line " + std::to_string(i);
    std::memcpy(s, line.data(), line.size());
    ring.publish(line.size());
  }
  done.store(true, std::memory_order_release);
  consumer.join();
  EXPECT_EQ(next, kLines);
  EXPECT_TRUE(bad.empty()) << bad.size() << " lines torn or out of order, first " << bad.front();
}

// A value the producer fills with its own sequence number everywhere (a torn copy mixes two numbers), with a length
// of its own: only the first `used` entries of `v` are pushed.
struct Record {
  std::uint64_t seq = 0;
  std::uint32_t used = 0;
  std::uint32_t pad = 0;
  std::uint64_t v[13] = {};  // sizeof 120: not a multiple of a cache line, 8-byte words only
};
struct OddRecord {  // a size that is not a multiple of 8
  char c[13] = {};
};

std::size_t bytes_of(const Record& r) { return offsetof(Record, v) + r.used * sizeof(std::uint64_t); }

Record numbered(std::uint64_t i, std::uint32_t used) {
  Record r;
  r.seq = i;
  r.used = used;
  for (std::uint32_t k = 0; k < used; ++k) r.v[k] = i;
  return r;
}

TEST(SeqlockRing, ReadsTheCommittedValueAndRefusesAnUncommittedOrOverwrittenOne) {
  SeqlockRing<Record> ring(4);
  Record got;
  EXPECT_FALSE(ring.read(0, got));  // nothing committed
  for (std::uint64_t i = 0; i < 6; ++i) {
    const Record r = numbered(100 + i, 13);
    ring.push(r, sizeof r);
  }
  EXPECT_EQ(ring.head(), 6u);
  EXPECT_FALSE(ring.read(1, got));  // overwritten by value 5
  ASSERT_TRUE(ring.read(5, got));
  EXPECT_EQ(got.seq, 105u);
  EXPECT_EQ(got.v[12], 105u);
  EXPECT_FALSE(ring.read(6, got));  // not committed yet
}

// Only the bytes pushed move: the rest of the reader's copy keeps what it held (a tick with 2 contacts copies 2,
// not 64), and a tail of doubles moves with its own length.
TEST(SeqlockRing, MovesOnlyTheBytesAndTailPushed) {
  SeqlockRing<Record> ring(2, 5);
  EXPECT_EQ(ring.tail_capacity(), 5u);
  const Record r = numbered(7, 2);
  const double tail[5] = {1.5, 2.5, 3.5, 4.5, 5.5};
  ring.push(r, bytes_of(r), tail, 3);
  Record got;
  for (auto& x : got.v) x = 99;
  double t[5] = {0, 0, 0, 0, -1};
  std::size_t count = 0;
  ASSERT_TRUE(ring.read(0, got, t, count));
  EXPECT_EQ(got.seq, 7u);
  EXPECT_EQ(got.v[0], 7u);
  EXPECT_EQ(got.v[1], 7u);
  EXPECT_EQ(got.v[2], 99u) << "an entry beyond the pushed length was copied";
  EXPECT_EQ(count, 3u);
  EXPECT_EQ(t[2], 3.5);
  EXPECT_EQ(t[4], -1.0) << "a double beyond the pushed tail was copied";
  // A tail longer than the capacity is cut to it; a length beyond sizeof(T) to sizeof(T).
  ring.push(r, 10 * sizeof r, tail, 50);
  ASSERT_TRUE(ring.read(1, got, t, count));
  EXPECT_EQ(count, 5u);
  EXPECT_EQ(t[4], 5.5);

  SeqlockRing<OddRecord> odd(2);
  OddRecord o;
  for (int k = 0; k < 13; ++k) o.c[k] = static_cast<char>('a' + k);
  odd.push(o, sizeof o);
  OddRecord back;
  ASSERT_TRUE(odd.read(0, back));
  EXPECT_EQ(std::string(back.c, 13), std::string(o.c, 13));
}

// A reader that falls behind a producer that never waits: every copy it accepts is whole (every word equals the
// sequence number it asked for, as many words as that value had) and none is torn; some are refused (overwritten).
// Under ThreadSanitizer (scripts/sanitize.sh thread) it is also free of data races: the copy that races with the
// producer reads atomic words.
TEST(SeqlockRing, AcceptedCopiesAreWholeWhileTheProducerOverwrites) {
  SeqlockRing<Record> ring(4, 6);
  constexpr std::uint64_t kValues = 300000;
  std::atomic<bool> done{false};
  std::atomic<std::uint64_t> accepted{0};
  std::uint64_t torn = 0;
  std::thread reader([&] {
    while (!done.load(std::memory_order_acquire)) {
      const std::uint64_t h = ring.head();
      if (h == 0) continue;
      const std::uint64_t i = h - 1;
      Record got;
      double tail[6];
      std::size_t count = 0;
      if (ring.read(i, got, tail, count)) {
        accepted.fetch_add(1, std::memory_order_relaxed);
        bool whole = got.seq == i && got.used == i % 14 && count == i % 7;
        for (std::uint32_t k = 0; whole && k < got.used; ++k) whole = got.v[k] == i;
        for (std::size_t k = 0; whole && k < count; ++k) whole = tail[k] == static_cast<double>(i);
        if (!whole) ++torn;
      }
    }
  });
  // At least kValues values, and on until the reader has accepted 1000 copies (it may start late).
  double tail[6];
  for (std::uint64_t i = 0; i < kValues || accepted.load(std::memory_order_relaxed) < 1000; ++i) {
    const Record r = numbered(i, static_cast<std::uint32_t>(i % 14));
    for (double& x : tail) x = static_cast<double>(i);
    ring.push(r, bytes_of(r), tail, i % 7);
  }
  done.store(true, std::memory_order_release);
  reader.join();
  EXPECT_GE(accepted.load(), 1000u);
  EXPECT_EQ(torn, 0u);
}

}  // namespace
}  // namespace surgsim::concurrency
