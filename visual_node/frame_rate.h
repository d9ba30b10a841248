// The visual node's measured frame rate (VisualStatus.fps): frames over a sliding window of the last second of
// frame completion times. With k frame intervals completed inside the window, fps = k / (their span); when the
// previous frame is older than the window (a renderer slower than 1 fps, or a stall), the newest interval alone.
// Fixed storage (a ring of the last kCapacity stamps; above kCapacity fps the window is the last kCapacity frames),
// no allocation: called from the frame loop.
#pragma once
#include <array>
#include <cstdint>

namespace surgsim {

class FrameRateMeter {
 public:
  static constexpr int kCapacity = 4096;

  explicit FrameRateMeter(double window_s = 1.0) noexcept
      : window_ns_(window_s > 0 ? static_cast<std::uint64_t>(window_s * 1e9) : 1) {}

  /// A frame finished at `t_ns` (monotonic, not decreasing).
  void add(std::uint64_t t_ns) noexcept {
    stamps_[static_cast<std::size_t>(count_ % kCapacity)] = t_ns;
    ++count_;
  }

  /// Frames per second over the window ending at the newest frame; 0 before two frames.
  double fps() const noexcept {
    if (count_ < 2) return 0;
    const std::uint64_t newest = at(count_ - 1);
    const std::uint64_t kept = count_ < kCapacity ? count_ : kCapacity;
    // The oldest kept stamp within the window: binary search over the logical indices [count_ - kept, count_ - 1)
    // (stamps do not decrease).
    std::uint64_t lo = count_ - kept, hi = count_ - 2;  // the answer is in [lo, hi + 1]; hi + 1 = newest interval only
    if (newest - at(hi) > window_ns_) return interval_fps(count_ - 2, newest);
    while (lo < hi) {
      const std::uint64_t mid = lo + (hi - lo) / 2;
      if (newest - at(mid) <= window_ns_) {
        hi = mid;
      } else {
        lo = mid + 1;
      }
    }
    return interval_fps(lo, newest);
  }

  std::uint64_t frames() const noexcept { return count_; }

 private:
  std::uint64_t at(std::uint64_t i) const noexcept { return stamps_[static_cast<std::size_t>(i % kCapacity)]; }
  double interval_fps(std::uint64_t first, std::uint64_t newest) const noexcept {
    const std::uint64_t span = newest - at(first);
    if (span == 0) return 0;
    return static_cast<double>(count_ - 1 - first) * 1e9 / static_cast<double>(span);
  }

  std::array<std::uint64_t, kCapacity> stamps_{};
  std::uint64_t count_ = 0;
  std::uint64_t window_ns_;
};

}  // namespace surgsim
