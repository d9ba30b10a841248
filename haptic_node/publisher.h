// The haptic node's publisher thread (nothing but physics on the loop thread). The loop fills one
// fixed-size tick record per tick into a preallocated ring and goes on; a publisher thread (SCHED_FIFO below the
// loop, like the DDS threads) writes ForceFeedback first, then ContactFrame, then the organ's own topics (the
// intestine's BodyState). The loop makes no DDS call and no allocation.
//
// Hand-off: the loop fills a record of its own (begin()), and commit() pushes it into a single-producer ring of
// `slots` records, each guarded by a sequence lock (version odd while the loop writes it), its payload moved through
// atomic words (concurrency/seqlock_ring.h: no data race, only the contacts the tick has). The producer never
// waits in real-time mode (a slot the publisher has not read yet is overwritten; the publisher sees the version change
// and skips it); the publisher copies a record out, checks the version, and writes from its copy. Wake-up: the
// publisher sleeps on a futex; the loop calls FUTEX_WAKE only when the publisher is asleep. FUTEX_WAKE never blocks (it
// takes a kernel hash-bucket spinlock and marks the waiter runnable): about 1-3 us, against up to 100 us of added force
// latency (and 10 000 wake-ups a second on 2 cores) for a publisher that polls every 100 us.
//
// Policies:
//  - Real-time (paced) runs: ForceFeedback is always the NEWEST record's (a force the publisher reaches late is never
//    sent: forces_skipped). ContactFrame and organ topics are written for every record in order while the publisher
//    is less than `slots / 2` records behind; further behind it jumps to the newest record and the stale ones are
//    skipped (counted in skipped()). A publisher that keeps up (the normal case) writes every tick.
//  - Normally scheduled paced runs (--rt-priority 0, or SCHED_FIFO refused: set_back_pressure(true)): forces as
//    above, but no frame is skipped: the producer waits while the ring is full (the publisher `slots` ticks behind).
//    Without SCHED_FIFO the OS may stall any thread for tens of ms anyway; every frame and BodyState is kept.
//  - Lossless (--speed max, tick-exact replay; and tests that drive tick() themselves): every record is written in
//    order, force then frame; the producer waits (yields) while the ring is full. No real-time promise is made.
//  - Overrun (paced runs): when the loop has not handed over tick k+1 by its deadline (tick k's due time + 2
//    periods), the publisher re-sends tick k's force with kFlagHeld, once per missed period: the first missed period
//    holds it, then it fades linearly to exactly zero `fade_ns` (10 ms) after the first missed deadline. Each such
//    sample counts in overrun_hold_ticks(). A fresh record is sent as computed the moment it arrives.
//  - Thinned frames (frame_every > 1, the scene's haptic.publish_hz): ContactFrame and the organ's topics go out for
//    one record in frame_every at most (seq 0, then the first record at least frame_every after the last written) and
//    for the last tick; the others are counted in thinned(). ForceFeedback is still every tick's.
//  - Shutdown (finish()): every record handed over is drained (the last tick's ForceFeedback and ContactFrame are
//    written), then a final zero ForceFeedback (seq = last tick + 1, the last tick's flags | kFlagHeld).
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <thread>
#include <type_traits>
#include <vector>

#include "concurrency/seqlock_ring.h"
#include "core/stats.h"
#include "organ.h"
#include "tool/trajectory.h"

namespace surgsim {

/// ForceFeedback / ContactFrame flag: this force was not computed for its tick but held, faded or zeroed by the
/// publisher (overrun, or the final zero at exit). The same value as msg::kFlagHeld of idl/Surgsim.idl (checked in
/// haptic_dds.cpp); kept here so that the publisher does not depend on the generated types.
inline constexpr std::uint32_t kFlagHeld = 32;

/// One instrument's part of a tick record.
struct InstrumentRecord {
  tool::Pose5 pose;
  RecordVec3 tip;
  RecordVec3 force;         // N, on the instrument (ContactFrame)
  RecordVec3 device_force;  // N, sent to its device (ForceFeedback)
  RecordVec3 direction;
  std::uint32_t flags = 0;
  std::uint32_t contact_points = 0;
  bool saturated = false;
};

/// One tick's outputs, everything the publisher writes. Trivially copyable and standard layout (the hand-off moves
/// it word by word, its organ's contacts last so that only those in use move); organ.points points into storage of
/// the side that holds the copy (the loop's own record, the publisher's copies).
struct TickRecord {
  std::uint64_t seq = 0;
  double sim_time = 0;          // s
  std::uint64_t due_ns = 0;     // monotonic time the tick was due (0: unpaced, no overrun watchdog)
  std::uint64_t period_ns = 0;  // loop period (0: unpaced)
  int instrument_count = 1;     // the scene's instruments, 1..kMaxInstruments
  std::array<InstrumentRecord, tool::kMaxInstruments> instruments{};
  std::uint32_t flags = 0;      // the union of the instruments' flags
  bool last_tick = false;       // the run's last tick: no overrun watchdog after it
  std::uint64_t commit_ns = 0;  // monotonic time of commit() (set by the publisher)
  OrganOutputs organ;           // last: its contacts are the record's variable-length tail
};
static_assert(std::is_trivially_copyable_v<TickRecord>, "the hand-off moves TickRecord word by word");
static_assert(std::is_standard_layout_v<TickRecord>, "record_bytes() takes offsetof in TickRecord");

/// The bytes of `r` the hand-off moves: everything up to its organ's contacts, and the first contact_count of those.
inline std::size_t record_bytes(const TickRecord& r) noexcept {
  const int n = std::clamp(r.organ.contact_count, 0, kMaxContactEntries);
  return offsetof(TickRecord, organ) + offsetof(OrganOutputs, contacts) +
         static_cast<std::size_t>(n) * sizeof(ContactRecord);
}

/// Where the publisher writes (HapticDds in the node, a recorder in tests). Called on the publisher thread only.
class TickSink {
 public:
  virtual ~TickSink() = default;
  /// Instrument `instrument`'s ForceFeedback.
  virtual void write_force(int instrument, std::uint64_t seq, std::uint64_t stamp_ns, const Eigen::Vector3d& force,
                           bool saturated, std::uint32_t flags) noexcept = 0;
  /// ContactFrame, then the organ's own topics.
  virtual void write_frame(const TickRecord& record, std::uint64_t stamp_ns) noexcept = 0;
};

/// Scale of the held force for the m-th missed period (m >= 1): 1 at m = 1 (hold), then linear to 0 at
/// (m - 1) * period >= fade (0 when fade <= 0 after the hold).
double overrun_scale(std::uint64_t missed, std::uint64_t period_ns, std::uint64_t fade_ns) noexcept;

struct PublisherOptions {
  std::size_t slots = 64;              // ring size (records)
  int body_points = 0;                 // organ positions per record (HapticOrgan::output_points())
  bool lossless = false;               // write every record, producer waits when full (--speed max)
  bool back_pressure = false;          // keep every frame, producer waits when full (implied by lossless)
  bool inline_writes = false;          // no thread: commit() writes on the caller's thread (the pre-issue-14 loop, kept
                                       // only to measure against: SURGSIM_HAPTIC_PUBLISHER=inline)
  std::uint64_t fade_ns = 10'000'000;  // overrun: from hold to zero
  std::size_t samples = 1 << 16;       // write-time samples kept for the percentiles
  std::uint64_t frame_every = 1;       // ContactFrame and organ topics for one record in this many at most (>= 1)
};

class Publisher {
 public:
  /// Allocates the ring and starts the publisher thread (it inherits the calling thread's scheduling: create it
  /// at the DDS threads' priority).
  Publisher(TickSink& sink, const PublisherOptions& options);
  ~Publisher();  // finish()
  Publisher(const Publisher&) = delete;
  Publisher& operator=(const Publisher&) = delete;

  /// Producer (the loop thread only), no allocation, no lock: the record to fill for the next tick (the loop's own:
  /// the publisher never reads it). With back-pressure it yields while the ring is full. Its organ.points has room
  /// for body_points positions.
  TickRecord& begin() noexcept;
  /// Hands the record over (pushes it into the ring) and wakes the publisher if it sleeps (one non-blocking
  /// FUTEX_WAKE).
  void commit() noexcept;
  /// Producer thread: wait when the ring is full instead of letting the publisher skip stale frames (for a loop that
  /// runs without SCHED_FIFO). Set before the first begin() or between ticks.
  void set_back_pressure(bool on) noexcept { back_pressure_.store(on || options_.lossless, std::memory_order_relaxed); }
  bool back_pressure() const { return back_pressure_.load(std::memory_order_relaxed); }

  /// Drains every committed record, writes the final zero force and joins. Idempotent. Not real-time.
  void finish();

  // Counters (exact after finish()).
  std::uint64_t committed() const { return ring_.head(std::memory_order_relaxed); }
  std::uint64_t written() const { return written_.load(std::memory_order_relaxed); }  // frames written
  std::uint64_t skipped() const { return skipped_.load(std::memory_order_relaxed); }  // frames never written
  /// Records whose frame was not written by design (frame_every): not in written() nor skipped().
  std::uint64_t thinned() const { return thinned_.load(std::memory_order_relaxed); }
  std::uint64_t forces_written() const { return forces_written_.load(std::memory_order_relaxed); }
  std::uint64_t forces_skipped() const { return forces_skipped_.load(std::memory_order_relaxed); }
  std::uint64_t overrun_hold_ticks() const { return hold_ticks_.load(std::memory_order_relaxed); }
  std::uint64_t overrun_faded_to_zero() const { return faded_to_zero_.load(std::memory_order_relaxed); }
  bool final_zero_sent() const { return final_zero_.load(std::memory_order_relaxed); }
  bool lossless() const { return options_.lossless; }
  bool inline_writes() const { return options_.inline_writes; }
  double fade_ms() const { return static_cast<double>(options_.fade_ns) * 1e-6; }
  /// After finish(): time to write one record (ForceFeedback + ContactFrame + organ topics, us) and from commit to
  /// the ForceFeedback written (us).
  core::Percentiles write_us() const { return write_us_.summary(); }
  core::Percentiles force_latency_us() const { return latency_us_.summary(); }

 private:
  void run() noexcept;
  /// Copies record i out of its slot into `out` (its points into `points`); false when it was overwritten.
  bool read(std::uint64_t i, TickRecord& out, double* points) const noexcept;
  void write_record_force(const TickRecord& r, std::uint64_t commit_ns) noexcept;
  /// The final zero force of every instrument of `last` (null: instrument 0 only, nothing was handed over).
  void write_zero(const TickRecord* last) noexcept;
  /// The record's ContactFrame and organ topics when due (frame_every), counted in written(); else in thinned().
  void write_frame_if_due(const TickRecord& r, std::uint64_t stamp_ns) noexcept;
  void wait_for(std::uint64_t seen_head, std::uint64_t deadline_ns) noexcept;

  TickSink& sink_;
  PublisherOptions options_;
  concurrency::SeqlockRing<TickRecord> ring_;  // the loop's records, read by the publisher thread (a sequence lock per
                                               // slot; the organ's points are each slot's tail)
  TickRecord filling_;                         // the loop's record between begin() and commit()
  std::vector<double> fill_points_;            // body_points * 3, filling_'s organ positions
  std::vector<double> copy_points_;            // the publisher's copies: [0] the frame record, [1] the newest (force)
  alignas(64) std::atomic<std::uint32_t> futex_{0};  // head_'s low bits, the publisher sleeps on it
  std::atomic<std::uint32_t> sleepers_{0};
  alignas(64) std::atomic<std::uint64_t> consumed_{0};  // records the publisher is done with (lossless back-pressure)
  std::atomic<bool> stop_{false};
  std::atomic<bool> back_pressure_{false};
  std::atomic<std::uint64_t> written_{0}, skipped_{0}, forces_written_{0}, forces_skipped_{0}, hold_ticks_{0},
      faded_to_zero_{0}, thinned_{0};
  std::uint64_t next_frame_seq_ = 0;  // frame_every: the first seq whose frame is due (the writing thread's only)
  std::atomic<bool> final_zero_{false};
  core::SampleRecorder write_us_;
  core::SampleRecorder latency_us_;
  std::thread thread_;
  bool finished_ = false;
  TickRecord inline_last_;  // inline_writes only
  bool inline_have_last_ = false;
};

}  // namespace surgsim
