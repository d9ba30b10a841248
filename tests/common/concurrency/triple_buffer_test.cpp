#include "concurrency/triple_buffer.h"

#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <thread>

using namespace surgsim::concurrency;

namespace surgsim::concurrency {
namespace {

TEST(TripleBuffer, ReaderSeesNothingUntilPublished) {
  TripleBuffer<int> buffer;
  EXPECT_FALSE(buffer.take());
  buffer.back() = 7;
  EXPECT_FALSE(buffer.take());  // written, not published
  buffer.publish();
  ASSERT_TRUE(buffer.take());
  EXPECT_EQ(buffer.front(), 7);
  EXPECT_FALSE(buffer.take());  // nothing new since
  EXPECT_EQ(buffer.front(), 7);
}

TEST(TripleBuffer, ReaderGetsTheNewestOfSeveralPublications) {
  TripleBuffer<int> buffer;
  for (int v = 1; v <= 5; ++v) {
    buffer.back() = v;
    buffer.publish();
  }
  ASSERT_TRUE(buffer.take());
  EXPECT_EQ(buffer.front(), 5);
}

TEST(TripleBuffer, TheWriterNeverWritesTheSlotTheReaderHolds) {
  TripleBuffer<int> buffer;
  buffer.back() = 1;
  buffer.publish();
  ASSERT_TRUE(buffer.take());
  const int* held = &buffer.front();
  for (int v = 2; v < 10; ++v) {
    EXPECT_NE(&buffer.back(), held);
    buffer.back() = v;
    buffer.publish();
  }
  EXPECT_EQ(*held, 1);
}

// A writer and a reader on two threads: every value taken is whole (all its words from one publication) and the
// sequence the reader sees never goes back.
TEST(TripleBuffer, ConcurrentValuesAreWholeAndInOrder) {
  using Value = std::array<long, 16>;
  TripleBuffer<Value> buffer;
  constexpr long kCount = 200000;
  std::atomic<bool> done{false};
  std::thread writer([&] {
    for (long v = 1; v <= kCount; ++v) {
      buffer.back().fill(v);
      buffer.publish();
    }
    done.store(true, std::memory_order_release);
  });
  long last = 0, torn = 0, backwards = 0;
  for (;;) {
    const bool finished = done.load(std::memory_order_acquire);
    if (buffer.take()) {
      const Value& value = buffer.front();
      for (long w : value) torn += w != value[0];
      backwards += value[0] < last;
      last = value[0];
    } else if (finished) {
      break;
    }
  }
  writer.join();
  EXPECT_EQ(torn, 0);
  EXPECT_EQ(backwards, 0);
  EXPECT_EQ(last, kCount);  // the last publication is always seen
}

}  // namespace
}  // namespace surgsim::concurrency
