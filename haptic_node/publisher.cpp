#include "publisher.h"

#include <linux/futex.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>

#include "core/clock.h"

using namespace surgsim::core;
using namespace surgsim::tool;

namespace surgsim {

namespace {

void futex_wake(std::atomic<std::uint32_t>* word) noexcept {
  syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(word), FUTEX_WAKE_PRIVATE, 1, nullptr, nullptr, 0);
}

// Sleeps while *word == expected, until woken or until the absolute monotonic time deadline_ns (0: no deadline).
void futex_wait(std::atomic<std::uint32_t>* word, std::uint32_t expected, std::uint64_t deadline_ns) noexcept {
  timespec ts{static_cast<time_t>(deadline_ns / 1000000000ull), static_cast<long>(deadline_ns % 1000000000ull)};
  // FUTEX_WAIT_BITSET takes an absolute CLOCK_MONOTONIC time.
  syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(word), FUTEX_WAIT_BITSET_PRIVATE, expected,
          deadline_ns != 0 ? &ts : nullptr, nullptr, FUTEX_BITSET_MATCH_ANY);
}

}  // namespace

double overrun_scale(std::uint64_t missed, std::uint64_t period_ns, std::uint64_t fade_ns) noexcept {
  if (missed <= 1) return 1.0;
  if (fade_ns == 0) return 0.0;
  const double s =
      1.0 - static_cast<double>(missed - 1) * static_cast<double>(period_ns) / static_cast<double>(fade_ns);
  return s > 0 ? s : 0.0;
}

Publisher::Publisher(TickSink& sink, const PublisherOptions& options)
    : sink_(sink),
      options_(options),
      ring_(std::max<std::size_t>(options.slots, 4), static_cast<std::size_t>(std::max(options.body_points, 0)) * 3),
      fill_points_(static_cast<std::size_t>(std::max(options.body_points, 0)) * 3 + 3),
      copy_points_(2 * static_cast<std::size_t>(std::max(options.body_points, 0)) * 3 + 3),
      write_us_(options.samples),
      latency_us_(options.samples) {
  filling_.organ.points = options_.body_points > 0 ? fill_points_.data() : nullptr;
  filling_.organ.point_capacity = std::max(options_.body_points, 0);
  back_pressure_.store(options_.lossless || options_.back_pressure);
  if (!options_.inline_writes) thread_ = std::thread([this] { run(); });
}

Publisher::~Publisher() { finish(); }

void Publisher::write_frame_if_due(const TickRecord& r, std::uint64_t stamp_ns) noexcept {
  if (r.seq < next_frame_seq_ && !r.last_tick) {
    thinned_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  next_frame_seq_ = r.seq + std::max<std::uint64_t>(options_.frame_every, 1);
  sink_.write_frame(r, stamp_ns);
  written_.fetch_add(1, std::memory_order_relaxed);
}

TickRecord& Publisher::begin() noexcept {
  const std::uint64_t i = ring_.head(std::memory_order_relaxed);
  const std::size_t n = ring_.size();
  if (back_pressure_.load(std::memory_order_relaxed)) {
    // Back-pressure (not real time): wait until the publisher is done with the record this slot held.
    for (int spins = 0; i - consumed_.load(std::memory_order_acquire) >= n; ++spins) {
      if (spins < 64) {
        std::this_thread::yield();
      } else {
        timespec ts{0, 20000};
        nanosleep(&ts, nullptr);
      }
    }
  }
  filling_.organ.contact_count = 0;
  filling_.organ.point_count = 0;
  return filling_;
}

void Publisher::commit() noexcept {
  const std::uint64_t i = ring_.head(std::memory_order_relaxed);
  TickRecord& r = filling_;
  r.commit_ns = monotonic_ns();
  const int points = std::clamp(r.organ.point_count, 0, std::max(options_.body_points, 0));
  ring_.push(r, record_bytes(r), r.organ.points, static_cast<std::size_t>(points) * 3);
  if (options_.inline_writes) {  // measurement only: the writes on the loop thread (no publisher thread)
    const std::uint64_t t0 = monotonic_ns();
    write_record_force(r, r.commit_ns);
    write_frame_if_due(r, monotonic_ns());
    write_us_.add(static_cast<double>(monotonic_ns() - t0) * 1e-3);
    inline_last_ = r;
    inline_have_last_ = true;
    consumed_.store(i + 1, std::memory_order_release);
    return;
  }
  futex_.store(static_cast<std::uint32_t>(i + 1), std::memory_order_seq_cst);
  if (sleepers_.load(std::memory_order_seq_cst) != 0) futex_wake(&futex_);
}

void Publisher::finish() {
  if (finished_) return;
  finished_ = true;
  stop_.store(true, std::memory_order_seq_cst);
  futex_.fetch_add(1u << 31, std::memory_order_seq_cst);  // any change wakes a sleeper
  futex_wake(&futex_);
  if (thread_.joinable()) thread_.join();
  if (options_.inline_writes) {
    write_zero(inline_have_last_ ? &inline_last_ : nullptr);
    final_zero_.store(true, std::memory_order_relaxed);
  }
}

bool Publisher::read(std::uint64_t i, TickRecord& out, double* points) const noexcept {
  std::size_t doubles = 0;
  if (!ring_.read(i, out, points, doubles)) return false;
  out.organ.contact_count = std::clamp(out.organ.contact_count, 0, kMaxContactEntries);
  out.organ.point_count =
      std::min(std::clamp(out.organ.point_count, 0, options_.body_points), static_cast<int>(doubles / 3));
  out.organ.point_capacity = options_.body_points;
  out.organ.points = points;
  return true;
}

void Publisher::write_zero(const TickRecord* last) noexcept {
  // Every instrument of the last record (the first otherwise) gets a zero force.
  const int n = last != nullptr ? std::clamp(last->instrument_count, 1, kMaxInstruments) : 1;
  for (int i = 0; i < n; ++i) {
    if (last != nullptr) {
      sink_.write_force(i, last->seq + 1, monotonic_ns(), Eigen::Vector3d::Zero(), false,
                        last->instruments[static_cast<std::size_t>(i)].flags | kFlagHeld);
    } else {
      sink_.write_force(i, 0, monotonic_ns(), Eigen::Vector3d::Zero(), false, kFlagHeld);
    }
  }
}

void Publisher::write_record_force(const TickRecord& r, std::uint64_t commit_ns) noexcept {
  const int n = std::clamp(r.instrument_count, 1, kMaxInstruments);
  for (int i = 0; i < n; ++i) {
    const InstrumentRecord& ir = r.instruments[static_cast<std::size_t>(i)];
    sink_.write_force(i, r.seq, monotonic_ns(), ir.device_force.eigen(), ir.saturated, ir.flags);
  }
  forces_written_.fetch_add(1, std::memory_order_relaxed);
  const std::uint64_t now = monotonic_ns();
  latency_us_.add(now > commit_ns ? static_cast<double>(now - commit_ns) * 1e-3 : 0.0);
}

void Publisher::wait_for(std::uint64_t seen_head, std::uint64_t deadline_ns) noexcept {
  const std::uint32_t expected = futex_.load(std::memory_order_seq_cst);
  sleepers_.fetch_add(1, std::memory_order_seq_cst);
  if (ring_.head(std::memory_order_seq_cst) == seen_head && !stop_.load(std::memory_order_seq_cst)) {
    futex_wait(&futex_, expected, deadline_ns);
  }
  sleepers_.fetch_sub(1, std::memory_order_seq_cst);
}

void Publisher::run() noexcept {
  const std::size_t per = static_cast<std::size_t>(std::max(options_.body_points, 0)) * 3;
  double* frame_points = copy_points_.data();
  double* force_points = copy_points_.data() + per;
  TickRecord frame;              // the record whose ContactFrame is written next
  TickRecord newest;             // the newest record (its force)
  std::uint64_t next_frame = 0;  // index of the next record whose frame is due
  std::uint64_t force_done = 0;  // records whose force was sent or superseded
  // The force the device holds now: for the overrun watchdog and the final zero.
  bool have_last = false;
  bool watch = false;             // the watchdog is armed for the last force
  std::uint64_t missed_sent = 0;  // missed periods already answered for it
  TickRecord last;
  const std::size_t lag_limit = ring_.size() / 2;

  for (;;) {
    const std::uint64_t h = ring_.head(std::memory_order_acquire);
    if (h > next_frame || h > force_done) {
      const std::uint64_t t0 = monotonic_ns();
      if (options_.lossless) {
        // Every record in order: its force, then its frame.
        const std::uint64_t i = next_frame;
        if (read(i, frame, frame_points)) {
          write_record_force(frame, frame.commit_ns);
          write_frame_if_due(frame, monotonic_ns());
          last = frame;
          have_last = true;
        } else {
          skipped_.fetch_add(1, std::memory_order_relaxed);  // cannot happen with back-pressure
        }
        next_frame = i + 1;
        force_done = next_frame;
        consumed_.store(next_frame, std::memory_order_release);
      } else {
        // The newest force first.
        const std::uint64_t n = h - 1;
        bool newest_ok = false;
        if (n >= force_done) {
          if (!read(n, newest, force_points)) continue;  // overwritten while copied: a newer one exists
          write_record_force(newest, newest.commit_ns);
          forces_skipped_.fetch_add(n - force_done, std::memory_order_relaxed);
          force_done = n + 1;
          newest_ok = true;
          last = newest;
          have_last = true;
          watch = newest.period_ns > 0 && newest.due_ns > 0 && !newest.last_tick;
          missed_sent = 0;
        }
        // Then the frames, in order while the publisher is close behind; far behind, from the newest on.
        if (n >= next_frame + lag_limit && !back_pressure_.load(std::memory_order_relaxed)) {
          skipped_.fetch_add(n - next_frame, std::memory_order_relaxed);
          next_frame = n;
        }
        if (next_frame <= n) {
          const std::uint64_t i = next_frame;
          bool ok = true;
          if (i == n && newest_ok) {
            write_frame_if_due(newest, monotonic_ns());
          } else if ((ok = read(i, frame, frame_points))) {
            write_frame_if_due(frame, monotonic_ns());
          }
          if (!ok) skipped_.fetch_add(1, std::memory_order_relaxed);
          next_frame = i + 1;
        }
        consumed_.store(next_frame, std::memory_order_release);
      }
      write_us_.add(static_cast<double>(monotonic_ns() - t0) * 1e-3);
      continue;
    }

    if (stop_.load(std::memory_order_acquire)) {
      if (ring_.head(std::memory_order_acquire) != h) continue;  // committed just before the stop
      // The final zero: the device is released when the node exits.
      write_zero(have_last ? &last : nullptr);
      final_zero_.store(true, std::memory_order_relaxed);
      return;
    }

    // Overrun watchdog: tick last.seq + 1 had to be handed over by last.due_ns + 2 periods.
    std::uint64_t deadline = 0;
    if (have_last && watch) {
      const std::uint64_t first_miss = last.due_ns + 2 * last.period_ns;
      deadline = first_miss + missed_sent * last.period_ns;
      const std::uint64_t now = monotonic_ns();
      if (now >= deadline) {
        const std::uint64_t m = (now - first_miss) / last.period_ns + 1;
        const double scale = overrun_scale(m, last.period_ns, options_.fade_ns);
        const int n = std::clamp(last.instrument_count, 1, kMaxInstruments);
        for (int i = 0; i < n; ++i) {
          const InstrumentRecord& ir = last.instruments[static_cast<std::size_t>(i)];
          sink_.write_force(i, last.seq, now, ir.device_force.eigen() * scale, ir.saturated && scale == 1.0,
                            ir.flags | kFlagHeld);
        }
        hold_ticks_.fetch_add(1, std::memory_order_relaxed);
        missed_sent = m;
        if (scale == 0.0) {
          faded_to_zero_.fetch_add(1, std::memory_order_relaxed);
          watch = false;  // zero sent: nothing more to hold until a fresh record
        }
        continue;
      }
    }
    wait_for(h, deadline);
  }
}

}  // namespace surgsim
