// Interposes malloc/calloc/realloc (glibc: forwards to __libc_*) to count the current thread's allocations while an
// AllocationCounter is alive. Eigen allocates with std::malloc and libstdc++'s operator new calls malloc, so this
// sees both.
#include "support/alloc_counter.h"

#include <cstddef>

extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
}

namespace {
thread_local bool t_counting = false;
thread_local long t_count = 0;
}  // namespace

extern "C" void* malloc(std::size_t n) {
  if (t_counting) ++t_count;
  return __libc_malloc(n);
}
extern "C" void* calloc(std::size_t a, std::size_t b) {
  if (t_counting) ++t_count;
  return __libc_calloc(a, b);
}
extern "C" void* realloc(void* p, std::size_t n) {
  if (t_counting) ++t_count;
  return __libc_realloc(p, n);
}

namespace surgsim::test {

AllocationCounter::AllocationCounter() {
  t_count = 0;
  t_counting = true;
}
AllocationCounter::~AllocationCounter() { t_counting = false; }
long AllocationCounter::count() const { return t_count; }

}  // namespace surgsim::test
