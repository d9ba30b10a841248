// The allocation counter the loop tests rely on: it must see malloc, operator new and Eigen's heap storage on the
// counting thread only, in the normal build and under AddressSanitizer or ThreadSanitizer (where it uses the
// sanitizer's allocation hook instead of interposing malloc). A counter that saw nothing would make every
// "allocates nothing" test pass.
#include "support/alloc_counter.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cstdlib>
#include <memory>
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

}  // namespace
}  // namespace surgsim::test
