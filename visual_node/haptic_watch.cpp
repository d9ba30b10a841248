#include "haptic_watch.h"

#include <algorithm>
#include <iostream>
#include <nlohmann/json.hpp>

namespace surgsim {

void HapticWatch::on_frame(std::uint64_t now_ns) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (first_frame_ns_ == 0) {
    first_frame_ns_ = now_ns;
    if (!quiet_) {
      std::cerr << "visual_node: first contact frame " << static_cast<double>(now_ns - start_ns_) * 1e-6
                << " ms after start\n";
    }
  }
  if (lost_) {
    lost_ = false;
    ++recoveries_;
    const double outage_ms = static_cast<double>(now_ns - last_frame_ns_) * 1e-6;
    outage_ms_max_ = std::max(outage_ms_max_, outage_ms);
    if (!quiet_) std::cerr << "visual_node: haptic node back after " << outage_ms << " ms without contact frames\n";
  }
  last_frame_ns_ = now_ns;
}

void HapticWatch::on_deadline_missed(std::uint64_t now_ns) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (lost_ || last_frame_ns_ == 0) return;  // already reported, or never seen
  lost_ = true;
  ++lost_events_;
  detect_ms_last_ = static_cast<double>(now_ns - last_frame_ns_) * 1e-6;
  detect_ms_max_ = std::max(detect_ms_max_, detect_ms_last_);
  if (!quiet_) {
    std::cerr << "visual_node: haptic node lost: no contact frame for " << detect_ms_last_
              << " ms (deadline missed); showing the last state until it returns\n";
  }
}

void HapticWatch::on_liveliness_changed(int alive, int lost_change, std::uint64_t now_ns) {
  if (lost_change <= 0) return;
  std::lock_guard<std::mutex> lock(mutex_);
  ++liveliness_lost_;
  if (!quiet_) {
    std::cerr << "visual_node: haptic participant not alive (liveliness lease expired, "
              << static_cast<double>(now_ns - last_frame_ns_) * 1e-6 << " ms after its last frame; " << alive
              << " haptic writers alive)\n";
  }
}

void HapticWatch::mark_dds_ready(std::uint64_t now_ns) {
  std::lock_guard<std::mutex> lock(mutex_);
  dds_ready_ns_ = now_ns;
}

bool HapticWatch::lost() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return lost_;
}

void HapticWatch::add_stats(nlohmann::json& j) const {
  std::lock_guard<std::mutex> lock(mutex_);
  j["haptic_lost_events"] = lost_events_;
  j["haptic_lost_detect_ms"] = {{"last", detect_ms_last_}, {"max", detect_ms_max_}};
  j["haptic_recoveries"] = recoveries_;
  j["haptic_outage_ms_max"] = outage_ms_max_;
  j["haptic_liveliness_lost"] = liveliness_lost_;
  j["haptic_lost_at_exit"] = lost_;
  j["dds_ready_ms"] = dds_ready_ns_ != 0 ? static_cast<double>(dds_ready_ns_ - start_ns_) * 1e-6 : -1.0;
  j["first_frame_ms"] = first_frame_ns_ != 0 ? static_cast<double>(first_frame_ns_ - start_ns_) * 1e-6 : -1.0;
}

}  // namespace surgsim
