// Lines from the real-time loop to a file without blocking the loop: a preallocated single-producer /
// single-consumer ring of fixed-size slots, drained by a writer thread that writes and flushes every few
// milliseconds (so a crash loses at most those lines). A full ring drops the line and counts it; never blocks.
#pragma once
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <thread>
#include <vector>

#include "concurrency/spsc_slot_ring.h"

namespace surgsim {

class AsyncLineWriter {
 public:
  /// Starts the writer thread on `file` (not owned; must stay open until this object is destroyed).
  /// `wait_when_full`: the producer yields until a slot frees instead of dropping (for unpaced, non-real-time
  /// runs such as --speed max, where every line must be kept).
  explicit AsyncLineWriter(std::FILE* file, bool wait_when_full = false, std::size_t slots = 1 << 14,
                           std::size_t slot_bytes = 256, int flush_ms = 5);
  /// Drains every committed line, flushes and joins (also done by the destructor).
  void finish();
  ~AsyncLineWriter();
  AsyncLineWriter(const AsyncLineWriter&) = delete;
  AsyncLineWriter& operator=(const AsyncLineWriter&) = delete;

  /// Producer side (one thread): a slot to format into, or null when the ring is full (the line is dropped and
  /// counted). No allocation, no lock, no system call.
  char* begin_line() noexcept;
  /// Publishes the slot taken by begin_line with `length` bytes (<= slot_bytes).
  void commit_line(std::size_t length) noexcept;
  std::size_t slot_bytes() const { return ring_.slot_bytes(); }
  std::uint64_t dropped() const { return dropped_.load(std::memory_order_relaxed); }
  std::uint64_t write_errors() const { return write_errors_.load(std::memory_order_relaxed); }

 private:
  void drain() noexcept;

  std::FILE* file_;
  bool wait_when_full_;
  int flush_ms_;
  concurrency::SpscSlotRing ring_;  // the loop's lines to the writer thread
  std::atomic<std::uint64_t> dropped_{0};
  std::atomic<std::uint64_t> write_errors_{0};
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace surgsim
