// Counts heap allocations (malloc, calloc, realloc, aligned_alloc, posix_memalign, memalign, valloc, pvalloc: what
// operator new, aligned operator new and Eigen use) made by the current thread inside a scope. Defined in
// alloc_counter.cpp, which interposes the C allocator for the whole test program.
#pragma once

namespace surgsim::test {

class AllocationCounter {
 public:
  AllocationCounter();   // starts counting for this thread
  ~AllocationCounter();  // stops
  long count() const;    // allocations so far in the scope
};

}  // namespace surgsim::test
