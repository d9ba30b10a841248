#include "async_writer.h"

#include <chrono>

namespace surgsim {

AsyncLineWriter::AsyncLineWriter(std::FILE* file, bool wait_when_full, std::size_t slots, std::size_t slot_bytes,
                                 int flush_ms)
    : file_(file), wait_when_full_(wait_when_full), slots_(slots), slot_bytes_(slot_bytes), flush_ms_(flush_ms), data_(slots * slot_bytes),
      length_(slots, 0) {
  thread_ = std::thread([this] {
    while (!stop_.load(std::memory_order_acquire)) {
      drain();
      // Sleep in 1 ms steps so that finish() never waits a whole flush period.
      for (int ms = 0; ms < flush_ms_ && !stop_.load(std::memory_order_acquire); ++ms) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
    }
    drain();
  });
}

void AsyncLineWriter::finish() {
  stop_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
}

AsyncLineWriter::~AsyncLineWriter() { finish(); }

char* AsyncLineWriter::begin_line() noexcept {
  const std::uint64_t head = head_.load(std::memory_order_relaxed);
  while (head - tail_.load(std::memory_order_acquire) >= slots_) {
    if (!wait_when_full_ || stop_.load(std::memory_order_relaxed)) {
      dropped_.fetch_add(1, std::memory_order_relaxed);
      return nullptr;
    }
    std::this_thread::yield();
  }
  return data_.data() + (head % slots_) * slot_bytes_;
}

void AsyncLineWriter::commit_line(std::size_t length) noexcept {
  const std::uint64_t head = head_.load(std::memory_order_relaxed);
  length_[head % slots_] = static_cast<std::uint32_t>(length < slot_bytes_ ? length : slot_bytes_);
  head_.store(head + 1, std::memory_order_release);
}

// Consumer: write every committed slot in order, then flush once.
void AsyncLineWriter::drain() noexcept {
  const std::uint64_t head = head_.load(std::memory_order_acquire);
  std::uint64_t tail = tail_.load(std::memory_order_relaxed);
  if (tail == head) return;
  for (; tail != head; ++tail) {
    const std::size_t slot = tail % slots_;
    const std::size_t n = length_[slot];
    if (std::fwrite(data_.data() + slot * slot_bytes_, 1, n, file_) != n) {
      write_errors_.fetch_add(1, std::memory_order_relaxed);
    }
    tail_.store(tail + 1, std::memory_order_release);
  }
  if (std::fflush(file_) != 0) write_errors_.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace surgsim
