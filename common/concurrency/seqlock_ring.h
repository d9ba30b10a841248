// A ring of values from one producer thread to readers that may fall behind, without locks or allocation: the
// producer never waits (it overwrites the oldest slot); a reader copies value i out and learns from the slot's
// version whether the producer overwrote it meanwhile (a sequence lock per slot).
#pragma once
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace surgsim::concurrency {

template <class T>
class SeqlockRing {
 public:
  /// `slots` slots (allocates here only). T must be trivially copyable in the parts the readers copy.
  explicit SeqlockRing(std::size_t slots) : slots_(slots) {}
  SeqlockRing(const SeqlockRing&) = delete;
  SeqlockRing& operator=(const SeqlockRing&) = delete;

  std::size_t size() const { return slots_.size(); }
  /// Values committed so far (value i is in slot i % size() until value i + size() is begun).
  std::uint64_t head(std::memory_order order = std::memory_order_acquire) const noexcept { return head_.load(order); }
  /// Slot s's value, for the owner's set-up before any thread runs (e.g. pointing each at its own storage).
  T& slot(std::size_t s) { return slots_[s].value; }

  /// Producer: the slot of value head() to fill (a reader of the value it held now fails), then commit().
  T& begin() noexcept {
    const std::uint64_t i = head_.load(std::memory_order_relaxed);
    Slot& s = slots_[i % slots_.size()];
    s.version.store(2 * i + 1, std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_release);
    return s.value;
  }
  /// Producer: the value begin() returned, until commit().
  T& writing() noexcept { return slots_[head_.load(std::memory_order_relaxed) % slots_.size()].value; }
  /// Producer: the value begin() returned is complete.
  void commit() noexcept {
    const std::uint64_t i = head_.load(std::memory_order_relaxed);
    slots_[i % slots_.size()].version.store(2 * (i + 1), std::memory_order_release);
    head_.store(i + 1, std::memory_order_release);
  }

  /// Reader: calls copy(const T&) on value i's slot; true when value i was committed and the slot still held it
  /// after the copy (false: not yet committed, or overwritten: discard what copy() took).
  template <class F>
  bool read(std::uint64_t i, F&& copy) const noexcept {
    const Slot& s = slots_[i % slots_.size()];
    const std::uint64_t v1 = s.version.load(std::memory_order_acquire);
    if (v1 != 2 * (i + 1)) return false;
    copy(s.value);  // may race with the producer overwriting the slot: the version check below discards it
    std::atomic_thread_fence(std::memory_order_acquire);
    return s.version.load(std::memory_order_relaxed) == v1;
  }

 private:
  struct Slot {
    std::atomic<std::uint64_t> version{0};  // 2i+1 while value i is written, 2(i+1) once committed
    T value{};
  };
  std::vector<Slot> slots_;
  alignas(64) std::atomic<std::uint64_t> head_{0};  // values committed
};

}  // namespace surgsim::concurrency
