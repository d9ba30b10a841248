// Counts heap allocations (malloc, calloc, realloc, aligned_alloc, posix_memalign, memalign, valloc, pvalloc: what
// operator new, aligned operator new and Eigen use) made by the current thread inside a scope, and can refuse the
// large ones. Defined in alloc_counter.cpp, which interposes the C allocator for the whole test program.
#pragma once
#include <cstddef>

namespace surgsim::test {

class AllocationCounter {
 public:
  AllocationCounter();   // starts counting for this thread
  ~AllocationCounter();  // stops
  long count() const;    // allocations so far in the scope
};

/// While alive, the current thread's requests of more than `max_bytes` fail (malloc returns null, so operator new
/// throws std::bad_alloc), and the largest request is recorded: a reader of sizes from a file can be shown never to
/// ask for a huge block without the memory being taken. Under a sanitizer the requests are only recorded (its
/// allocator owns malloc and cannot be told to fail), so a test checks largest() too.
class AllocationCeiling {
 public:
  explicit AllocationCeiling(std::size_t max_bytes);
  ~AllocationCeiling();
  std::size_t largest() const;  // bytes of the largest request so far in the scope (refused or not)
};

}  // namespace surgsim::test
