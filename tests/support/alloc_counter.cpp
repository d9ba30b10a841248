// Counts the current thread's allocations while an AllocationCounter is alive: interposes every allocating entry of
// the C allocator - malloc, calloc, realloc and the aligned ones, aligned_alloc, posix_memalign, memalign, valloc and
// pvalloc (glibc: forwards to __libc_*) - or under a sanitizer installs the sanitizer's allocation hook. Eigen
// allocates with std::malloc, libstdc++'s operator new calls malloc and its aligned operator new aligned_alloc, so
// either sees them all.
#include "support/alloc_counter.h"

#include <cerrno>
#include <cstddef>

namespace {
thread_local bool t_counting = false;
thread_local long t_count = 0;
thread_local bool t_ceiling_on = false;  // an AllocationCeiling is alive on this thread
thread_local std::size_t t_ceiling = 0;
thread_local std::size_t t_largest = 0;

// Counts a request of n bytes; false when an AllocationCeiling refuses it.
bool admit(std::size_t n) {
  if (t_counting) ++t_count;
  if (!t_ceiling_on) return true;
  if (n > t_largest) t_largest = n;
  return n <= t_ceiling;
}
}  // namespace

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
// Under AddressSanitizer or ThreadSanitizer the sanitizer owns malloc (an interposed malloc would hand its memory to
// the sanitizer's free): the count comes from the sanitizer's own allocation hook, which AddressSanitizer runs for
// every allocation of the process whatever the entry (malloc, calloc, realloc, aligned_alloc, posix_memalign,
// memalign, valloc, pvalloc, every operator new), ThreadSanitizer for all but the aligned C entries (below).
// Declared here: GCC installs the runtime (libasan, libtsan) but not clang's <sanitizer/allocator_interface.h>.
extern "C" int __sanitizer_install_malloc_and_free_hooks(void (*malloc_hook)(const volatile void*, std::size_t),
                                                         void (*free_hook)(const volatile void*));

namespace {
void on_malloc(const volatile void*, std::size_t n) { admit(n); }
void on_free(const volatile void*) {}
[[maybe_unused]] const int g_hooks_installed = __sanitizer_install_malloc_and_free_hooks(on_malloc, on_free);
}  // namespace
#if defined(__SANITIZE_THREAD__)
// ThreadSanitizer's runtime (GCC 12's) runs the hook from malloc, calloc, realloc and operator new but not from its
// aligned C entries: those are taken over here, counted, and handed to its own implementation (__interceptor_*, which
// the runtime exports beside the weak names this file takes over).
extern "C" {
void* __interceptor_memalign(std::size_t, std::size_t);
void* __interceptor_aligned_alloc(std::size_t, std::size_t);
int __interceptor_posix_memalign(void**, std::size_t, std::size_t);
void* __interceptor_valloc(std::size_t);
void* __interceptor_pvalloc(std::size_t);
}
extern "C" void* memalign(std::size_t alignment, std::size_t n) {
  admit(n);
  return __interceptor_memalign(alignment, n);
}
extern "C" void* aligned_alloc(std::size_t alignment, std::size_t n) {
  admit(n);
  return __interceptor_aligned_alloc(alignment, n);
}
extern "C" int posix_memalign(void** out, std::size_t alignment, std::size_t n) {
  admit(n);
  return __interceptor_posix_memalign(out, alignment, n);
}
extern "C" void* valloc(std::size_t n) {
  admit(n);
  return __interceptor_valloc(n);
}
extern "C" void* pvalloc(std::size_t n) {
  admit(n);
  return __interceptor_pvalloc(n);
}
#endif
#else
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void* __libc_valloc(std::size_t);
void* __libc_pvalloc(std::size_t);
}

namespace {
void* refused() {
  errno = ENOMEM;
  return nullptr;
}
}  // namespace

extern "C" void* malloc(std::size_t n) { return admit(n) ? __libc_malloc(n) : refused(); }
extern "C" void* calloc(std::size_t a, std::size_t b) {
  std::size_t n = 0;
  if (__builtin_mul_overflow(a, b, &n)) n = static_cast<std::size_t>(-1);
  return admit(n) ? __libc_calloc(a, b) : refused();
}
extern "C" void* realloc(void* p, std::size_t n) { return admit(n) ? __libc_realloc(p, n) : refused(); }
// The aligned entries. glibc exports no __libc_ name for aligned_alloc and posix_memalign: they are memalign behind
// their own checks of the alignment, as glibc makes them.
namespace {
bool power_of_two(std::size_t n) { return n != 0 && (n & (n - 1)) == 0; }
}  // namespace

extern "C" void* memalign(std::size_t alignment, std::size_t n) {
  return admit(n) ? __libc_memalign(alignment, n) : refused();
}
extern "C" void* aligned_alloc(std::size_t alignment, std::size_t n) {
  if (!admit(n)) return refused();
  if (!power_of_two(alignment)) {
    errno = EINVAL;
    return nullptr;
  }
  return __libc_memalign(alignment, n);
}
extern "C" int posix_memalign(void** out, std::size_t alignment, std::size_t n) {
  if (!admit(n)) return ENOMEM;
  if (!power_of_two(alignment) || alignment % sizeof(void*) != 0) return EINVAL;
  void* p = __libc_memalign(alignment, n);
  if (p == nullptr) return ENOMEM;
  *out = p;
  return 0;
}
extern "C" void* valloc(std::size_t n) { return admit(n) ? __libc_valloc(n) : refused(); }
extern "C" void* pvalloc(std::size_t n) { return admit(n) ? __libc_pvalloc(n) : refused(); }
#endif

namespace surgsim::test {

AllocationCounter::AllocationCounter() {
  t_count = 0;
  t_counting = true;
}
AllocationCounter::~AllocationCounter() { t_counting = false; }
long AllocationCounter::count() const { return t_count; }

AllocationCeiling::AllocationCeiling(std::size_t max_bytes) {
  t_largest = 0;
  t_ceiling = max_bytes;
  t_ceiling_on = true;
}
AllocationCeiling::~AllocationCeiling() { t_ceiling_on = false; }
std::size_t AllocationCeiling::largest() const { return t_largest; }

}  // namespace surgsim::test
