// A ring of fixed-size byte slots from one producer thread to one consumer thread, without locks or allocation after
// construction: the producer claims a slot, fills it and publishes its length; the consumer takes the published slots
// in order. The producer's and the consumer's counters sit on cache lines of their own.
#pragma once
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace surgsim::concurrency {

class SpscSlotRing {
 public:
  /// `slots` slots of `slot_bytes` bytes each (allocates here only).
  SpscSlotRing(std::size_t slots, std::size_t slot_bytes)
      : slots_(slots), slot_bytes_(slot_bytes), data_(slots * slot_bytes), length_(slots, 0) {}
  SpscSlotRing(const SpscSlotRing&) = delete;
  SpscSlotRing& operator=(const SpscSlotRing&) = delete;

  std::size_t slots() const { return slots_; }
  std::size_t slot_bytes() const { return slot_bytes_; }

  /// Producer: the next slot to fill, or null while the ring is full (every slot published and not yet consumed).
  char* claim() noexcept {
    const std::uint64_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_.load(std::memory_order_acquire) >= slots_) return nullptr;
    return data_.data() + (head % slots_) * slot_bytes_;
  }
  /// Producer: publishes the slot claim() returned with its first `length` bytes (at most slot_bytes()).
  void publish(std::size_t length) noexcept {
    const std::uint64_t head = head_.load(std::memory_order_relaxed);
    length_[head % slots_] = static_cast<std::uint32_t>(length < slot_bytes_ ? length : slot_bytes_);
    head_.store(head + 1, std::memory_order_release);
  }

  /// Consumer: calls f(const char* data, std::size_t length) on every slot published so far, oldest first, freeing
  /// each after its call; the number of slots taken.
  template <class F>
  std::size_t consume(F&& f) noexcept {
    const std::uint64_t head = head_.load(std::memory_order_acquire);
    std::uint64_t tail = tail_.load(std::memory_order_relaxed);
    std::size_t n = 0;
    for (; tail != head; ++tail, ++n) {
      const std::size_t slot = tail % slots_;
      f(static_cast<const char*>(data_.data() + slot * slot_bytes_), static_cast<std::size_t>(length_[slot]));
      tail_.store(tail + 1, std::memory_order_release);
    }
    return n;
  }
  /// Slots published and not yet consumed (either thread; a snapshot).
  std::size_t size() const noexcept {
    return static_cast<std::size_t>(head_.load(std::memory_order_acquire) - tail_.load(std::memory_order_acquire));
  }

 private:
  std::size_t slots_;
  std::size_t slot_bytes_;
  std::vector<char> data_;
  std::vector<std::uint32_t> length_;
  alignas(64) std::atomic<std::uint64_t> head_{0};          // slots published (the producer's counter)
  alignas(64) std::atomic<std::uint64_t> tail_{0};          // slots consumed (the consumer's counter)
  char pad_[64 - sizeof(std::atomic<std::uint64_t>)] = {};  // nothing after tail_ shares its line
};

}  // namespace surgsim::concurrency
