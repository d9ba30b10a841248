// Counts the current thread's allocations while an AllocationCounter is alive: interposes malloc/calloc/realloc
// (glibc: forwards to __libc_*), or under a sanitizer installs the sanitizer's allocation hook. Eigen allocates with
// std::malloc and libstdc++'s operator new calls malloc, so either sees both.
#include "support/alloc_counter.h"

#include <cstddef>

namespace {
thread_local bool t_counting = false;
thread_local long t_count = 0;
}  // namespace

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
// Under AddressSanitizer or ThreadSanitizer the sanitizer owns malloc (an interposed malloc would hand its memory to
// the sanitizer's free): the count comes from the sanitizer's own allocation hook, which sees every malloc, calloc,
// realloc and operator new of the process.
// Declared here: GCC installs the runtime (libasan, libtsan) but not clang's <sanitizer/allocator_interface.h>.
extern "C" int __sanitizer_install_malloc_and_free_hooks(void (*malloc_hook)(const volatile void*, std::size_t),
                                                         void (*free_hook)(const volatile void*));

namespace {
void on_malloc(const volatile void*, std::size_t) {
  if (t_counting) ++t_count;
}
void on_free(const volatile void*) {}
[[maybe_unused]] const int g_hooks_installed = __sanitizer_install_malloc_and_free_hooks(on_malloc, on_free);
}  // namespace
#else
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
}

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
#endif

namespace surgsim::test {

AllocationCounter::AllocationCounter() {
  t_count = 0;
  t_counting = true;
}
AllocationCounter::~AllocationCounter() { t_counting = false; }
long AllocationCounter::count() const { return t_count; }

}  // namespace surgsim::test
