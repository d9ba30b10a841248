// A CPU wake-up latency request (Linux PM QoS, /dev/cpu_dma_latency), as real-time programs such as cyclictest make.
// Why (measured on the 2-core KVM CI machine): an idle virtual CPU halts (cpuidle "haltpoll" state, HLT)
// and hands its physical CPU back to the host; when the loop's timer fires, the host must schedule that virtual CPU
// again first, which took 0.5-7 ms now and then. Every missed deadline of the haptic node pinned alone on its CPU
// was such a late wake-up. While a request of 0 us is held, idle CPUs poll instead of halting (the kernel drops
// every idle state with a longer exit latency), and the same 1 kHz timer woke late by at most 0.2-0.9 ms instead of
// 2.6-7.5 ms (rt_bench). The cost: idle CPUs stay busy for the host while the request is held.
// The request is the kernel's own: it holds while the file stays open and ends when it is closed (or the process
// exits), so nothing outlives the program.
#pragma once
#include <string>

namespace surgsim::os {

class CpuLatencyRequest {
 public:
  /// max_us >= 0: asks that no CPU take longer than max_us microseconds to leave idle (0: idle CPUs poll). < 0: asks
  /// nothing. Never throws: what was refused (no /dev/cpu_dma_latency, not root) is in note().
  explicit CpuLatencyRequest(int max_us);
  ~CpuLatencyRequest();  // withdraws the request
  CpuLatencyRequest(const CpuLatencyRequest&) = delete;
  CpuLatencyRequest& operator=(const CpuLatencyRequest&) = delete;

  bool held() const { return fd_ >= 0; }
  /// e.g. "CPU wake-up latency <= 0 us (idle CPUs poll)", "no CPU latency request (-1)",
  /// "CPU latency request refused (/dev/cpu_dma_latency: Permission denied)".
  const std::string& note() const { return note_; }

  /// The latency the kernel currently grants every CPU (the smallest request of any process), us; -1 when unknown.
  static long current_us();

 private:
  int fd_ = -1;
  std::string note_;
};

}  // namespace surgsim::os
