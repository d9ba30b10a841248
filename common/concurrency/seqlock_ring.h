// A ring of values from one producer thread to readers that may fall behind, without locks or allocation: the
// producer never waits (it overwrites the oldest slot); a reader copies value i out and learns from the slot's
// version whether the producer overwrote it meanwhile (a sequence lock per slot).
//
// The payload moves through atomic 64-bit words, never through plain loads and stores: a reader that copies a slot
// while the producer rewrites it reads atomics the producer writes, which is defined behaviour (the copy is torn, and
// the version check discards it), where a plain copy of the same bytes would be a data race. The producer stores the
// words with release order and the reader loads them with acquire order (no fences, which ThreadSanitizer does not
// model): a reader that sees any word of a new value also sees the odd version stored before it, and its second
// version load cannot move before its word loads. On x86-64 both are ordinary moves. Each value carries its own length, so a record with a variable-length
// tail (the contacts a tick has, out of the 64 it may have) moves only the bytes in use, and a second, optional
// array of doubles per slot (the intestine's body positions) moves the same way.
#pragma once
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>
#include <vector>

namespace surgsim::concurrency {

template <class T>
class SeqlockRing {
  static_assert(std::is_trivially_copyable_v<T>,
                "SeqlockRing copies values word by word: T must be trivially copyable");

 public:
  /// `slots` slots, each with room for a T and `tail_doubles` doubles (allocates here only).
  explicit SeqlockRing(std::size_t slots, std::size_t tail_doubles = 0)
      : slots_(slots < 1 ? 1 : slots),
        tail_doubles_(tail_doubles),
        stride_(kValueWords + tail_doubles),
        versions_(slots_),
        words_(slots_ * stride_) {}
  SeqlockRing(const SeqlockRing&) = delete;
  SeqlockRing& operator=(const SeqlockRing&) = delete;

  std::size_t size() const { return slots_; }
  std::size_t tail_capacity() const { return tail_doubles_; }
  /// Values committed so far (value i is in slot i % size() until value i + size() is pushed).
  std::uint64_t head(std::memory_order order = std::memory_order_acquire) const noexcept { return head_.load(order); }

  /// Producer: value head() is the first `bytes` bytes of `value` (at most sizeof(T)) and the first `tail_count`
  /// doubles of `tail` (at most tail_capacity()). A reader copying the value this slot held now fails.
  void push(const T& value, std::size_t bytes, const double* tail = nullptr, std::size_t tail_count = 0) noexcept {
    if (bytes > sizeof(T)) bytes = sizeof(T);
    if (tail == nullptr) tail_count = 0;
    if (tail_count > tail_doubles_) tail_count = tail_doubles_;
    const std::uint64_t i = head_.load(std::memory_order_relaxed);
    const std::size_t s = static_cast<std::size_t>(i % slots_);
    Version& v = versions_[s];
    v.version.store(2 * i + 1, std::memory_order_relaxed);  // ordered before the words by their release stores
    std::atomic<std::uint64_t>* w = &words_[s * stride_];
    const auto* src = reinterpret_cast<const unsigned char*>(&value);
    const std::size_t full = bytes / 8;
    for (std::size_t k = 0; k < full; ++k) {
      std::uint64_t x;
      std::memcpy(&x, src + 8 * k, 8);
      w[k].store(x, std::memory_order_release);
    }
    if (bytes % 8 != 0) {
      std::uint64_t x = 0;
      std::memcpy(&x, src + 8 * full, bytes % 8);
      w[full].store(x, std::memory_order_release);
    }
    for (std::size_t k = 0; k < tail_count; ++k) {
      std::uint64_t x;
      std::memcpy(&x, tail + k, 8);
      w[kValueWords + k].store(x, std::memory_order_release);
    }
    v.bytes.store(static_cast<std::uint32_t>(bytes), std::memory_order_release);
    v.tail.store(static_cast<std::uint32_t>(tail_count), std::memory_order_release);
    v.version.store(2 * (i + 1), std::memory_order_release);
    head_.store(i + 1, std::memory_order_release);
  }

  /// Reader: copies value i into `out` (the bytes the producer pushed; the rest of `out` is left as it was) and its
  /// tail into `tail` (room for tail_capacity() doubles; null: not copied), its length into `tail_count`. True when
  /// value i was committed and the slot still held it after the copy; false (not yet committed, or overwritten
  /// meanwhile): discard what was copied.
  bool read(std::uint64_t i, T& out, double* tail, std::size_t& tail_count) const noexcept {
    const std::size_t s = static_cast<std::size_t>(i % slots_);
    const Version& v = versions_[s];
    const std::uint64_t v1 = v.version.load(std::memory_order_acquire);
    if (v1 != 2 * (i + 1)) return false;
    std::size_t bytes = v.bytes.load(std::memory_order_acquire);
    std::size_t count = v.tail.load(std::memory_order_acquire);
    if (bytes > sizeof(T)) bytes = sizeof(T);  // torn lengths: bounded here, discarded below
    if (count > tail_doubles_) count = tail_doubles_;
    const std::atomic<std::uint64_t>* w = &words_[s * stride_];
    auto* dst = reinterpret_cast<unsigned char*>(&out);
    const std::size_t full = bytes / 8;
    for (std::size_t k = 0; k < full; ++k) {
      const std::uint64_t x = w[k].load(std::memory_order_acquire);
      std::memcpy(dst + 8 * k, &x, 8);
    }
    if (bytes % 8 != 0) {
      const std::uint64_t x = w[full].load(std::memory_order_acquire);
      std::memcpy(dst + 8 * full, &x, bytes % 8);
    }
    if (tail != nullptr) {
      for (std::size_t k = 0; k < count; ++k) {
        const std::uint64_t x = w[kValueWords + k].load(std::memory_order_acquire);
        std::memcpy(tail + k, &x, 8);
      }
    }
    tail_count = tail != nullptr ? count : 0;
    return v.version.load(std::memory_order_relaxed) == v1;
  }
  /// Reader: read() without a tail.
  bool read(std::uint64_t i, T& out) const noexcept {
    std::size_t ignored = 0;
    return read(i, out, nullptr, ignored);
  }

 private:
  static constexpr std::size_t kValueWords = (sizeof(T) + 7) / 8;
  struct alignas(64) Version {
    std::atomic<std::uint64_t> version{0};  // 2i+1 while value i is written, 2(i+1) once committed
    std::atomic<std::uint32_t> bytes{0};    // bytes of the value pushed
    std::atomic<std::uint32_t> tail{0};     // doubles of the tail pushed
  };
  std::size_t slots_;
  std::size_t tail_doubles_;
  std::size_t stride_;  // words per slot
  std::vector<Version> versions_;
  std::vector<std::atomic<std::uint64_t>> words_;
  alignas(64) std::atomic<std::uint64_t> head_{0};  // values committed
};

}  // namespace surgsim::concurrency
