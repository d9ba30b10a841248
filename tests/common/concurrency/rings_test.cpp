// The single-producer rings: the slot ring (lines from the loop to a writer thread) and the sequence-locked ring (the
// loop's records to the publisher), alone and between two real threads.
#include <gtest/gtest.h>

#include <atomic>
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

struct Record {
  std::uint64_t a = 0, b = 0;  // the producer writes a, then b = a: a torn copy has a != b
};

TEST(SeqlockRing, ReadsTheCommittedValueAndRefusesAnUncommittedOrOverwrittenOne) {
  SeqlockRing<Record> ring(4);
  Record got;
  EXPECT_FALSE(ring.read(0, [&](const Record& r) { got = r; }));  // nothing committed
  for (std::uint64_t i = 0; i < 6; ++i) {
    Record& r = ring.begin();
    r.a = r.b = 100 + i;
    EXPECT_EQ(&ring.writing(), &r);
    ring.commit();
  }
  EXPECT_EQ(ring.head(), 6u);
  EXPECT_FALSE(ring.read(1, [&](const Record& r) { got = r; }));  // overwritten by value 5
  ASSERT_TRUE(ring.read(5, [&](const Record& r) { got = r; }));
  EXPECT_EQ(got.a, 105u);
  ring.begin();  // value 6 is being written in value 2's slot: value 2 is gone
  EXPECT_FALSE(ring.read(2, [&](const Record& r) { got = r; }));
  EXPECT_FALSE(ring.read(6, [&](const Record& r) { got = r; }));  // not committed yet
}

// Fields the two threads may touch at once (the copy races with the producer by design: relaxed atomics make that
// race defined; the version check decides whether the copy counts).
struct SharedRecord {
  std::atomic<std::uint64_t> a{0}, b{0};
};

// A reader that falls behind a producer that never waits: every copy it accepts is whole (a == b) and is the value
// it asked for; some are refused (overwritten), none is torn.
TEST(SeqlockRing, AcceptedCopiesAreWholeWhileTheProducerOverwrites) {
  SeqlockRing<SharedRecord> ring(4);
  constexpr std::uint64_t kValues = 300000;
  std::atomic<bool> done{false};
  std::atomic<std::uint64_t> accepted{0};
  std::uint64_t torn = 0;
  std::thread reader([&] {
    std::uint64_t i = 0;
    while (!done.load(std::memory_order_acquire)) {
      const std::uint64_t h = ring.head();
      if (h == 0) continue;
      i = h - 1;
      Record got;
      if (ring.read(i, [&](const SharedRecord& r) {
            got.a = r.a.load(std::memory_order_relaxed);
            got.b = r.b.load(std::memory_order_relaxed);
          })) {
        accepted.fetch_add(1, std::memory_order_relaxed);
        if (got.a != got.b || got.a != i) ++torn;
      }
    }
  });
  // At least kValues values, and on until the reader has accepted 1000 copies (it may start late).
  for (std::uint64_t i = 0; i < kValues || accepted.load(std::memory_order_relaxed) < 1000; ++i) {
    SharedRecord& r = ring.begin();
    r.a.store(i, std::memory_order_relaxed);
    r.b.store(i, std::memory_order_relaxed);
    ring.commit();
  }
  done.store(true, std::memory_order_release);
  reader.join();
  EXPECT_GE(accepted.load(), 1000u);
  EXPECT_EQ(torn, 0u);
}

}  // namespace
}  // namespace surgsim::concurrency
