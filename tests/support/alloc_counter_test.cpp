// The allocation counter the loop tests rely on: it must see malloc, operator new and Eigen's heap storage on the
// counting thread only, and every other allocating entry (calloc, realloc, the aligned ones, aligned operator new), in
// the normal build and under AddressSanitizer or ThreadSanitizer (where it uses the sanitizer's allocation hook instead
// of interposing malloc). A counter that saw nothing would make every "allocates nothing" test pass.
#include "support/alloc_counter.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cstdlib>
#include <malloc.h>
#include <memory>
#include <new>
#include <thread>
#include <vector>

namespace surgsim::test {
namespace {

TEST(AllocationCounter, SeesMallocNewAndEigenOnItsThreadOnly) {
  AllocationCounter counter;
  EXPECT_EQ(counter.count(), 0);
  void* volatile p = std::malloc(64);
  std::free(p);
  EXPECT_EQ(counter.count(), 1);
  auto q = std::make_unique<std::vector<int>>(100);
  EXPECT_GE(counter.count(), 3) << "operator new (the vector object and its storage)";
  const long before = counter.count();
  Eigen::VectorXd v(1000);
  v.setZero();
  EXPECT_GT(counter.count(), before) << "Eigen's heap storage";
  const long mine = counter.count();
  std::thread([] { std::free(std::malloc(32)); }).join();
  // The thread object itself may allocate on this thread (its state), but the other thread's malloc is not counted:
  // at most the thread's own bookkeeping here.
  EXPECT_LE(counter.count() - mine, 2);
}

TEST(AllocationCounter, CountsNothingOutsideItsScope) {
  long inside = 0;
  {
    AllocationCounter counter;
    inside = counter.count();
  }
  std::free(std::malloc(8));
  AllocationCounter again;
  EXPECT_EQ(again.count(), 0);
  EXPECT_EQ(inside, 0);
}

// The ceiling the cache-reader tests use: a request above it is refused (operator new throws std::bad_alloc, so a
// reader that sized a vector from a forged count fails without taking the memory), one below it is served, and the
// largest request is recorded either way.
TEST(AllocationCeiling, RefusesLargeRequestsAndRecordsTheLargest) {
  std::size_t largest = 0;
  {
    AllocationCeiling ceiling(1 << 20);
    void* volatile p = std::malloc(1000);  // volatile: the compiler may not elide the call
    EXPECT_NE(p, nullptr);
    std::free(p);
    EXPECT_GE(ceiling.largest(), 1000u);
#if !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
    EXPECT_THROW(p = ::operator new (std::size_t{64} << 20), std::bad_alloc);
    p = std::malloc(std::size_t{2} << 20);
    EXPECT_EQ(p, nullptr);
    const volatile std::size_t huge = std::size_t{1} << 40;  // volatile: no compile-time size warning
    p = std::calloc(huge, huge);                             // the product overflows
    EXPECT_EQ(p, nullptr);
    EXPECT_EQ(ceiling.largest(), static_cast<std::size_t>(-1));
#endif
    largest = ceiling.largest();
  }
  EXPECT_GE(largest, 1000u);
  // Gone with its scope: a large request is served again.
  void* volatile p = std::malloc(std::size_t{2} << 20);
  EXPECT_NE(p, nullptr);
  std::free(p);
}

// Each allocating entry of the C allocator counts once, the aligned ones too, and aligned operator new (libstdc++ takes
// its memory from aligned_alloc): a loop that allocated through an entry the counter missed would pass its
// "allocates nothing" test.
TEST(AllocationCounter, SeesEveryAllocatingEntry) {
  struct Entry {
    const char* name;
    void* (*allocate)();
  };
  const Entry entries[] = {
      {"calloc", [] { return std::calloc(4, 16); }},
      {"realloc of nothing", [] { return std::realloc(nullptr, 64); }},
      {"aligned_alloc", [] { return std::aligned_alloc(64, 128); }},
      {"posix_memalign",
       [] {
         void* p = nullptr;
         return posix_memalign(&p, 64, 128) == 0 ? p : nullptr;
       }},
      {"memalign", [] { return memalign(64, 128); }},
      {"valloc", [] { return valloc(128); }},
      {"pvalloc", [] { return pvalloc(128); }},
  };
  AllocationCounter counter;
  for (const Entry& e : entries) {
    const long before = counter.count();
    void* volatile p = e.allocate();  // volatile: the compiler may not elide the call
    EXPECT_NE(p, nullptr) << e.name;
    EXPECT_EQ(counter.count() - before, 1) << e.name;
    std::free(p);
  }
  void* volatile grown = std::malloc(16);
  long before = counter.count();
  grown = std::realloc(grown, std::size_t{1} << 16);
  EXPECT_EQ(counter.count() - before, 1) << "realloc to a larger block";
  std::free(grown);
  before = counter.count();
  void* volatile aligned = ::operator new (256, std::align_val_t{64});
  EXPECT_EQ(counter.count() - before, 1) << "aligned operator new";
  ::operator delete (aligned, std::align_val_t{64});
}

}  // namespace
}  // namespace surgsim::test
