#include "async_writer.h"

#include <chrono>

namespace surgsim {

AsyncLineWriter::AsyncLineWriter(std::FILE* file, bool wait_when_full, std::size_t slots, std::size_t slot_bytes,
                                 int flush_ms)
    : file_(file), wait_when_full_(wait_when_full), flush_ms_(flush_ms), ring_(slots, slot_bytes) {
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
  for (;;) {
    if (char* slot = ring_.claim()) return slot;
    if (!wait_when_full_ || stop_.load(std::memory_order_relaxed)) {
      dropped_.fetch_add(1, std::memory_order_relaxed);
      return nullptr;
    }
    std::this_thread::yield();
  }
}

void AsyncLineWriter::commit_line(std::size_t length) noexcept { ring_.publish(length); }

// Consumer: write every committed slot in order, then flush once.
void AsyncLineWriter::drain() noexcept {
  const std::size_t taken = ring_.consume([this](const char* data, std::size_t n) {
    if (std::fwrite(data, 1, n, file_) != n) write_errors_.fetch_add(1, std::memory_order_relaxed);
  });
  if (taken == 0) return;
  if (std::fflush(file_) != 0) write_errors_.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace surgsim
