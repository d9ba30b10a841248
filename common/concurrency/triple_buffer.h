// The latest-value hand-off between two threads (one writer, one reader), without locks or allocation.
#pragma once
#include <array>
#include <atomic>
#include <cstddef>

namespace surgsim::concurrency {

/// Single-producer single-consumer latest-value exchange (three slots, one atomic): the writer never waits for the
/// reader and the reader never waits for the writer; the reader sees the newest complete value. Slots are
/// allocated by the caller at init (resize each of slot(0..2)); publish()/take() allocate nothing.
template <class T>
class TripleBuffer {
 public:
  T& slot(int i) { return slots_[static_cast<std::size_t>(i)]; }
  /// The writer's slot: fill it, then publish().
  T& back() { return slots_[static_cast<std::size_t>(back_)]; }
  void publish() noexcept { back_ = middle_.exchange(back_ | kFresh, std::memory_order_acq_rel) & kIndex; }
  /// The reader: takes the newest published value if there is one since the last take(); true then.
  bool take() noexcept {
    if ((middle_.load(std::memory_order_acquire) & kFresh) == 0) return false;
    front_ = middle_.exchange(front_, std::memory_order_acq_rel) & kIndex;
    return true;
  }
  /// The reader's current value (after take()).
  const T& front() const { return slots_[static_cast<std::size_t>(front_)]; }

 private:
  static constexpr int kFresh = 4, kIndex = 3;
  std::array<T, 3> slots_{};
  int back_ = 0, front_ = 1;
  std::atomic<int> middle_{2};
};

}  // namespace surgsim::concurrency
