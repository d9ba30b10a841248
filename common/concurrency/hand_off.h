// One object handed from one thread to another without locks, allocation or deallocation on either side's hot path:
// the sender posts an owned object into a single slot; the receiver takes it (ownership moves with the pointer).
#pragma once
#include <atomic>
#include <memory>

namespace surgsim::concurrency {

template <class T>
class HandOff {
 public:
  HandOff() = default;
  ~HandOff() { delete slot_.load(std::memory_order_acquire); }
  HandOff(const HandOff&) = delete;
  HandOff& operator=(const HandOff&) = delete;

  /// Sender: posts `value` when the slot is empty (true), else leaves it with the caller (false). No allocation.
  bool post(std::unique_ptr<T>& value) noexcept {
    T* expected = nullptr;
    if (!slot_.compare_exchange_strong(expected, value.get(), std::memory_order_acq_rel)) return false;
    value.release();
    return true;
  }
  /// Receiver: the posted object, or null. No allocation.
  std::unique_ptr<T> take() noexcept { return std::unique_ptr<T>(slot_.exchange(nullptr, std::memory_order_acq_rel)); }
  /// Either side: whether an object waits in the slot (a snapshot).
  bool full() const noexcept { return slot_.load(std::memory_order_acquire) != nullptr; }

 private:
  std::atomic<T*> slot_{nullptr};
};

}  // namespace surgsim::concurrency
