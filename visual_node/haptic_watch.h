// Watches the haptic node from the visual side. The ContactFrame reader requests a deadline (100 ms in
// config/dds/profiles.xml): a missed deadline while frames were flowing means "haptic node lost"; the next frame
// means "back". Liveliness (automatic, 1 s lease) tells a dead haptic participant from a stalled loop. Each change
// is logged once and counted for the stats JSON. Called from DDS listener threads; all methods are thread-safe.
#pragma once
#include <cstdint>
#include <mutex>
#include <nlohmann/json_fwd.hpp>

namespace surgsim {

class HapticWatch {
 public:
  /// `start_ns`: when the node started (monotonic), the origin of first_frame_ms.
  explicit HapticWatch(std::uint64_t start_ns, bool quiet = false) : start_ns_(start_ns), quiet_(quiet) {}

  /// A contact frame arrived at `now_ns`.
  void on_frame(std::uint64_t now_ns);
  /// The reader's requested deadline was missed (Fast DDS calls this once per period without a frame).
  void on_deadline_missed(std::uint64_t now_ns);
  /// Liveliness of the matched haptic writers changed: `alive` writers now, `lost_change` that just went not-alive.
  void on_liveliness_changed(int alive, int lost_change, std::uint64_t now_ns);

  /// The DDS entities exist (origin of the discovery part of first_frame_ms).
  void mark_dds_ready(std::uint64_t now_ns);
  bool lost() const;
  /// Adds haptic_lost_events, haptic_lost_detect_ms {last, max}, haptic_recoveries, haptic_outage_ms_max,
  /// haptic_liveliness_lost, haptic_lost_at_exit, dds_ready_ms, first_frame_ms to the stats.
  void add_stats(nlohmann::json& j) const;

 private:
  mutable std::mutex mutex_;
  std::uint64_t start_ns_;
  bool quiet_;
  bool lost_ = false;
  std::uint64_t dds_ready_ns_ = 0;
  std::uint64_t first_frame_ns_ = 0;
  std::uint64_t last_frame_ns_ = 0;
  std::uint64_t lost_events_ = 0;
  std::uint64_t recoveries_ = 0;
  std::uint64_t liveliness_lost_ = 0;
  double detect_ms_last_ = 0;  // last frame -> loss detected
  double detect_ms_max_ = 0;
  double outage_ms_max_ = 0;   // last frame before a loss -> first frame after it
};

}  // namespace surgsim
