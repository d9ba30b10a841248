// The publisher thread's hand-off (haptic_node/publisher.h): order of the writes (force first, then the frame),
// every tick in lossless mode, the newest force first when the publisher falls behind, the jump to the newest frame
// when it falls far behind, the overrun hold-and-fade, the final zero, and that the producer's thread never writes.
// Deterministic: backlogs are made by a sink that blocks until the test releases it; no timing is asserted.
#include "publisher.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <vector>

#include "core/clock.h"
#include "support/alloc_counter.h"

using namespace surgsim::core;

namespace surgsim {
namespace {

struct Event {
  char kind;  // 'F' force, 'C' contact frame
  std::uint64_t seq;
  Eigen::Vector3d force;
  std::uint32_t flags;
  std::thread::id thread;
  int points;
  double first_point;
  int instrument = 0;
};

class RecordingSink : public TickSink {
 public:
  void write_force(int instrument, std::uint64_t seq, std::uint64_t, const Eigen::Vector3d& force, bool,
                   std::uint32_t flags) noexcept override {
    gate();
    std::lock_guard<std::mutex> lock(mutex_);
    events_.push_back({'F', seq, force, flags, std::this_thread::get_id(), 0, 0, instrument});
  }
  void write_frame(const TickRecord& r, std::uint64_t) noexcept override {
    std::lock_guard<std::mutex> lock(mutex_);
    events_.push_back({'C', r.seq, r.instruments[0].force, r.flags, std::this_thread::get_id(), r.organ.point_count,
                       r.organ.point_count > 0 ? r.organ.points[0] : 0.0});
  }
  /// The next write_force blocks until release() (and signals blocked()).
  void hold_next() {
    std::lock_guard<std::mutex> lock(gate_mutex_);
    hold_ = true;
  }
  void wait_blocked() {
    std::unique_lock<std::mutex> lock(gate_mutex_);
    cv_.wait(lock, [&] { return blocked_; });
  }
  void release() {
    std::lock_guard<std::mutex> lock(gate_mutex_);
    hold_ = false;
    cv_.notify_all();
  }
  std::vector<Event> events() {
    std::lock_guard<std::mutex> lock(mutex_);
    return events_;
  }
  std::size_t size() {
    std::lock_guard<std::mutex> lock(mutex_);
    return events_.size();
  }

 private:
  void gate() {
    std::unique_lock<std::mutex> lock(gate_mutex_);
    if (!hold_) return;
    blocked_ = true;
    cv_.notify_all();
    cv_.wait(lock, [&] { return !hold_; });
    blocked_ = false;
  }
  std::mutex mutex_;
  std::vector<Event> events_;
  std::mutex gate_mutex_;
  std::condition_variable cv_;
  bool hold_ = false;
  bool blocked_ = false;
};

void push(Publisher& p, std::uint64_t seq, double fx, std::uint64_t due_ns = 0, std::uint64_t period_ns = 0,
          bool last = false, int instruments = 1) {
  TickRecord& r = p.begin();
  r.seq = seq;
  r.sim_time = static_cast<double>(seq) * 1e-3;
  r.due_ns = due_ns;
  r.period_ns = period_ns;
  r.instrument_count = instruments;
  for (int i = 0; i < instruments; ++i) {  // instrument i pushes with (i + 1) fx
    InstrumentRecord& ir = r.instruments[static_cast<std::size_t>(i)];
    ir.device_force = Eigen::Vector3d((i + 1) * fx, 0, 0);
    ir.force = ir.device_force;
    ir.flags = 0;
  }
  r.flags = 0;
  r.last_tick = last;
  for (int i = 0; i < r.organ.point_capacity; ++i) {
    r.organ.points[3 * i] = static_cast<double>(seq);
    r.organ.points[3 * i + 1] = 0;
    r.organ.points[3 * i + 2] = 0;
  }
  r.organ.point_count = r.organ.point_capacity;
  p.commit();
}

std::vector<std::uint64_t> seqs(const std::vector<Event>& ev, char kind, bool held) {
  std::vector<std::uint64_t> out;
  for (const auto& e : ev) {
    if (e.kind == kind && ((e.flags & kFlagHeld) != 0) == held) out.push_back(e.seq);
  }
  return out;
}

TEST(Publisher, OverrunHoldsOnePeriodThenFadesLinearlyToZero) {
  const std::uint64_t ms = 1'000'000;
  EXPECT_EQ(overrun_scale(1, ms, 10 * ms), 1.0);  // the first missed deadline: hold
  EXPECT_NEAR(overrun_scale(2, ms, 10 * ms), 0.9, 1e-12);
  EXPECT_NEAR(overrun_scale(6, ms, 10 * ms), 0.5, 1e-12);
  EXPECT_EQ(overrun_scale(11, ms, 10 * ms), 0.0);  // zero 10 ms after the first missed deadline
  EXPECT_EQ(overrun_scale(50, ms, 10 * ms), 0.0);
  EXPECT_NEAR(overrun_scale(2, ms / 3 * 10, 10 * ms), 1.0 - 1.0 / 3.0, 1e-6);  // 300 Hz: zero after 3-4 periods
  EXPECT_EQ(overrun_scale(5, ms / 3 * 10, 10 * ms), 0.0);
}

// --speed max: every record, its force before its frame, in order, from the publisher's thread; then a final zero.
TEST(Publisher, LosslessWritesEveryTickForceFirstOffTheProducerThread) {
  RecordingSink sink;
  PublisherOptions o;
  o.slots = 8;  // small: the producer waits for the publisher many times
  o.lossless = true;
  o.body_points = 5;
  Publisher p(sink, o);
  const std::uint64_t n = 2000;
  {
    test::AllocationCounter counter;
    for (std::uint64_t k = 0; k < n; ++k) push(p, k, 1.0 + static_cast<double>(k));
    EXPECT_EQ(counter.count(), 0) << "begin()/commit() allocate nothing";
  }
  p.finish();
  const auto ev = sink.events();
  ASSERT_EQ(ev.size(), 2 * n + 1);
  for (std::uint64_t k = 0; k < n; ++k) {
    EXPECT_EQ(ev[2 * k].kind, 'F');
    EXPECT_EQ(ev[2 * k].seq, k);
    EXPECT_EQ(ev[2 * k].force.x(), 1.0 + static_cast<double>(k));
    EXPECT_EQ(ev[2 * k + 1].kind, 'C');
    EXPECT_EQ(ev[2 * k + 1].seq, k);
    EXPECT_EQ(ev[2 * k + 1].points, 5);
    EXPECT_EQ(ev[2 * k + 1].first_point, static_cast<double>(k)) << "the body positions of the same tick";
  }
  for (const auto& e : ev) EXPECT_NE(e.thread, std::this_thread::get_id()) << "a write on the producer's thread";
  EXPECT_EQ(ev.back().kind, 'F');
  EXPECT_EQ(ev.back().seq, n);
  EXPECT_EQ(ev.back().force, Eigen::Vector3d::Zero());
  EXPECT_NE(ev.back().flags & kFlagHeld, 0u);
  EXPECT_EQ(p.written(), n);
  EXPECT_EQ(p.skipped(), 0u);
  EXPECT_EQ(p.forces_written(), n);
  EXPECT_TRUE(p.final_zero_sent());
  EXPECT_EQ(p.write_us().count, n);
}

// Real-time mode, a publisher a few ticks behind: the newest force goes out first, the frames follow in order.
TEST(Publisher, BehindSendsTheNewestForceFirstThenEveryFrame) {
  RecordingSink sink;
  PublisherOptions o;
  o.slots = 64;
  Publisher p(sink, o);
  sink.hold_next();
  push(p, 0, 1.0);
  sink.wait_blocked();  // the publisher is inside the force write of tick 0
  for (std::uint64_t k = 1; k <= 5; ++k) push(p, k, 1.0 + static_cast<double>(k));
  sink.release();
  p.finish();
  const auto ev = sink.events();
  std::string order;
  for (const auto& e : ev) order += e.kind + std::to_string(e.seq) + " ";
  EXPECT_EQ(order, "F0 C0 F5 C1 C2 C3 C4 C5 F6 ");
  EXPECT_EQ(p.forces_written(), 2u);
  EXPECT_EQ(p.forces_skipped(), 4u) << "the forces of ticks 1-4 were stale before they could go out";
  EXPECT_EQ(p.written(), 6u);
  EXPECT_EQ(p.skipped(), 0u);
  EXPECT_EQ(ev.back().force, Eigen::Vector3d::Zero());
}

// Real-time mode, a publisher far behind (the ring wrapped): it jumps to the newest record and counts the rest.
TEST(Publisher, FarBehindSkipsStaleFramesAndNeverWaitsTheProducer) {
  RecordingSink sink;
  PublisherOptions o;
  o.slots = 8;
  o.body_points = 3;
  Publisher p(sink, o);
  sink.hold_next();
  push(p, 0, 1.0);
  sink.wait_blocked();
  for (std::uint64_t k = 1; k <= 20; ++k) push(p, k, 1.0 + static_cast<double>(k));  // 2.5 rings: no waiting
  sink.release();
  p.finish();
  const auto ev = sink.events();
  std::string order;
  for (const auto& e : ev) order += e.kind + std::to_string(e.seq) + " ";
  EXPECT_EQ(order, "F0 C0 F20 C20 F21 ");
  EXPECT_EQ(ev[3].first_point, 20.0) << "the frame carries its own tick's positions";
  EXPECT_EQ(p.written(), 2u);
  EXPECT_EQ(p.skipped(), 19u);
  EXPECT_EQ(p.forces_skipped(), 19u);
  EXPECT_EQ(p.written() + p.skipped(), p.committed());
}

// frame_every (haptic.publish_hz): every tick's force, but the frame (and the organ's topics) of one tick in
// frame_every and of the last tick; the others are counted as thinned, neither written nor skipped.
TEST(Publisher, ThinnedFramesEveryForceAndTheLastTicksFrame) {
  RecordingSink sink;
  PublisherOptions o;
  o.lossless = true;
  o.frame_every = 4;
  Publisher p(sink, o);
  for (std::uint64_t k = 0; k <= 10; ++k) push(p, k, 1.0 + static_cast<double>(k), 0, 0, k == 10);
  p.finish();
  std::string order;
  for (const auto& e : sink.events()) order += e.kind + std::to_string(e.seq) + " ";
  EXPECT_EQ(order, "F0 C0 F1 F2 F3 F4 C4 F5 F6 F7 F8 C8 F9 F10 C10 F11 ");
  EXPECT_EQ(p.written(), 4u);
  EXPECT_EQ(p.thinned(), 7u);
  EXPECT_EQ(p.skipped(), 0u);
  EXPECT_EQ(p.forces_written(), 11u);
}

// Real-time mode behind, thinned: the newest force first, then the due frames in order (seq 3, 6, 9 after 0).
TEST(Publisher, BehindAndThinnedWritesTheDueFramesInOrder) {
  RecordingSink sink;
  PublisherOptions o;
  o.slots = 64;
  o.frame_every = 3;
  Publisher p(sink, o);
  sink.hold_next();
  push(p, 0, 1.0);
  sink.wait_blocked();  // the publisher is inside the force write of tick 0
  for (std::uint64_t k = 1; k <= 9; ++k) push(p, k, 1.0 + static_cast<double>(k));
  sink.release();
  p.finish();
  std::string order;
  for (const auto& e : sink.events()) order += e.kind + std::to_string(e.seq) + " ";
  EXPECT_EQ(order, "F0 C0 F9 C3 C6 C9 F10 ");
  EXPECT_EQ(p.written(), 4u);
  EXPECT_EQ(p.thinned(), 6u);
  EXPECT_EQ(p.written() + p.skipped() + p.thinned(), p.committed());
}

// A paced loop without SCHED_FIFO: the newest force first, but no frame skipped (the producer waits when full).
TEST(Publisher, BackPressureKeepsEveryFrame) {
  RecordingSink sink;
  PublisherOptions o;
  o.slots = 8;
  o.back_pressure = true;
  Publisher p(sink, o);
  sink.hold_next();
  push(p, 0, 1.0);
  sink.wait_blocked();
  std::thread producer([&] {
    for (std::uint64_t k = 1; k <= 40; ++k) push(p, k, 1.0 + static_cast<double>(k));  // waits at tick 8
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  sink.release();
  producer.join();
  p.finish();
  EXPECT_EQ(p.written(), 41u);
  EXPECT_EQ(p.skipped(), 0u);
  std::vector<std::uint64_t> expected(41);
  for (std::uint64_t k = 0; k <= 40; ++k) expected[k] = k;
  const auto ev = sink.events();
  EXPECT_EQ(seqs(ev, 'C', false), expected) << "every frame, in order";
  EXPECT_EQ(p.forces_written() + p.forces_skipped(), 41u);
  EXPECT_EQ(ev.back().seq, 41u);
}

// A loop that stops handing ticks over: the device gets the last force held, then faded linearly to exactly zero,
// each flagged kFlagHeld; the next fresh tick is sent as computed.
TEST(Publisher, OverrunHoldsThenFadesTheLastForceToZero) {
  RecordingSink sink;
  PublisherOptions o;
  o.fade_ns = 20'000'000;  // 20 ms at a 2 ms period: hold, then 10 steps down
  Publisher p(sink, o);
  const std::uint64_t period = 2'000'000;
  push(p, 7, 4.0, monotonic_ns(), period);
  // Functional wait (generous: a loaded machine may wake the publisher late; the content does not depend on it).
  for (int i = 0; i < 2000 && p.overrun_faded_to_zero() == 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_EQ(p.overrun_faded_to_zero(), 1u);
  std::this_thread::sleep_for(std::chrono::milliseconds(10));  // nothing more once zero was sent
  const std::size_t after_zero = sink.size();
  push(p, 8, 2.0, monotonic_ns(), period, /*last=*/true);
  p.finish();
  const auto ev = sink.events();
  ASSERT_EQ(ev.size(), after_zero + 3);  // F8 C8 and the final zero
  std::vector<double> held;
  for (const auto& e : ev) {
    if (e.kind == 'F' && (e.flags & kFlagHeld) != 0 && e.seq == 7) held.push_back(e.force.x());
  }
  ASSERT_FALSE(held.empty());
  EXPECT_EQ(held.size(), p.overrun_hold_ticks());
  for (std::size_t i = 0; i < held.size(); ++i) {
    EXPECT_GE(held[i], 0.0);
    EXPECT_LE(held[i], 4.0);
    if (i > 0) {
      EXPECT_LT(held[i], held[i - 1]) << "the held force only goes down";
    }
    // Every held force is one of the steps of the fade: 4 N * (1 - (m - 1) * 2 / 20).
    const double steps = (1.0 - held[i] / 4.0) * 10.0;
    EXPECT_NEAR(steps, std::round(steps), 1e-9) << held[i];
  }
  EXPECT_EQ(held.back(), 0.0);
  EXPECT_EQ(seqs(ev, 'F', false), (std::vector<std::uint64_t>{7, 8}));
  EXPECT_EQ(ev[ev.size() - 3].force.x(), 2.0) << "the fresh tick as computed";
  EXPECT_EQ(ev.back().seq, 9u);
  EXPECT_EQ(ev.back().force, Eigen::Vector3d::Zero());
}

// The run's last tick arms no watchdog (the final zero follows at finish()).
TEST(Publisher, NoHoldAfterTheLastTick) {
  RecordingSink sink;
  Publisher p(sink, PublisherOptions{});
  push(p, 0, 3.0, monotonic_ns(), 1'000'000, /*last=*/true);
  std::this_thread::sleep_for(std::chrono::milliseconds(30));
  p.finish();
  EXPECT_EQ(p.overrun_hold_ticks(), 0u);
  std::string order;
  for (const auto& e : sink.events()) order += e.kind + std::to_string(e.seq) + " ";
  EXPECT_EQ(order, "F0 C0 F1 ");
}

// Several instruments: each instrument's force goes out as its own ForceFeedback (its key), in instrument order before
// the frame; an overrun holds and fades every instrument's force, and the final zero releases every device.
TEST(Publisher, EveryInstrumentGetsItsOwnForceHoldAndFinalZero) {
  RecordingSink sink;
  PublisherOptions o;
  o.lossless = true;
  {
    Publisher p(sink, o);
    push(p, 0, 1.0, 0, 0, false, 2);
    push(p, 1, 3.0, 0, 0, true, 2);
    p.finish();
  }
  std::string order;
  for (const auto& e : sink.events())
    order += e.kind + std::to_string(e.seq) + (e.kind == 'F' ? "/" + std::to_string(e.instrument) : "") + " ";
  EXPECT_EQ(order, "F0/0 F0/1 C0 F1/0 F1/1 C1 F2/0 F2/1 ");
  const auto ev = sink.events();
  EXPECT_EQ(ev[0].force.x(), 1.0);
  EXPECT_EQ(ev[1].force.x(), 2.0) << "instrument 1's own force";
  EXPECT_EQ(ev[4].force.x(), 6.0);
  EXPECT_EQ(ev[6].force, Eigen::Vector3d::Zero());
  EXPECT_EQ(ev[7].force, Eigen::Vector3d::Zero());
  EXPECT_NE(ev[7].flags & kFlagHeld, 0u);

  RecordingSink late;
  PublisherOptions f;
  f.fade_ns = 10'000'000;
  Publisher q(late, f);
  push(q, 4, 2.0, monotonic_ns(), 2'000'000, false, 2);
  for (int i = 0; i < 2000 && q.overrun_faded_to_zero() == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_EQ(q.overrun_faded_to_zero(), 1u);
  q.finish();
  std::vector<double> held[2];
  for (const auto& e : late.events())
    if (e.kind == 'F' && (e.flags & kFlagHeld) != 0 && e.seq == 4) held[e.instrument].push_back(e.force.x());
  ASSERT_EQ(held[0].size(), q.overrun_hold_ticks());
  ASSERT_EQ(held[1].size(), held[0].size());
  for (std::size_t i = 0; i < held[0].size(); ++i) EXPECT_EQ(held[1][i], 2 * held[0][i]) << "step " << i;
  EXPECT_EQ(held[1].back(), 0.0);
}

// Checks every field of each record the publisher writes against its sequence number: the producer fills every
// field of record k from k, so a copy that mixes two ticks shows. Counts in atomics (the publisher thread writes).
class NumberedSink : public TickSink {
 public:
  explicit NumberedSink(int body_points) : body_points_(body_points) {}
  void write_force(int instrument, std::uint64_t seq, std::uint64_t, const Eigen::Vector3d& force, bool saturated,
                   std::uint32_t flags) noexcept override {
    const double k = static_cast<double>(seq);
    const bool ok = (flags & kFlagHeld) != 0 ||  // the final zero
                    (force == Eigen::Vector3d(k, k + instrument, -k) && saturated == (seq % 2 == 1) &&
                     flags == static_cast<std::uint32_t>(seq & 0xff));
    (ok ? forces_ok_ : bad_).fetch_add(1, std::memory_order_relaxed);
  }
  void write_frame(const TickRecord& r, std::uint64_t) noexcept override {
    const std::uint64_t k = r.seq;
    const double d = static_cast<double>(k);
    bool ok = r.sim_time == d && r.due_ns == 0 && r.period_ns == 0 && r.flags == static_cast<std::uint32_t>(k & 0xff) &&
              r.instrument_count == 1 + static_cast<int>(k % tool::kMaxInstruments) &&
              r.organ.contact_count == static_cast<int>(k % (kMaxContactEntries + 1)) &&
              r.organ.point_count == static_cast<int>(k % static_cast<std::uint64_t>(body_points_ + 1)) &&
              r.organ.point_capacity == body_points_;
    for (int i = 0; ok && i < r.instrument_count; ++i) {
      const InstrumentRecord& ir = r.instruments[static_cast<std::size_t>(i)];
      ok = ir.pose.pitch == d && ir.pose.jaw == d && ir.tip.eigen() == Eigen::Vector3d(d, d, d) &&
           ir.force.eigen() == Eigen::Vector3d(d, -d, d) && ir.device_force.eigen() == Eigen::Vector3d(d, d + i, -d) &&
           ir.direction.eigen() == Eigen::Vector3d(-d, d, d) && ir.contact_points == static_cast<std::uint32_t>(k) &&
           ir.flags == static_cast<std::uint32_t>(k & 0xff) && ir.saturated == (k % 2 == 1);
    }
    for (int l = 0; ok && l < r.organ.contact_count; ++l) {
      const ContactRecord& c = r.organ.contacts[static_cast<std::size_t>(l)];
      ok = c.node == static_cast<int>(k) && c.instrument == l && c.lambda.eigen() == Eigen::Vector3d(d, d, l) &&
           c.u_tilde.eigen() == Eigen::Vector3d(l, d, d);
    }
    for (int j = 0; ok && j < 3 * r.organ.point_count; ++j) ok = r.organ.points[j] == d + j;
    (ok ? frames_ok_ : bad_).fetch_add(1, std::memory_order_relaxed);
    if (!ok && first_bad_.load(std::memory_order_relaxed) == 0) first_bad_.store(k + 1, std::memory_order_relaxed);
  }
  std::uint64_t frames_ok() const { return frames_ok_.load(); }
  std::uint64_t forces_ok() const { return forces_ok_.load(); }
  std::uint64_t bad() const { return bad_.load(); }
  std::uint64_t first_bad() const { return first_bad_.load(); }

 private:
  int body_points_;
  std::atomic<std::uint64_t> frames_ok_{0}, forces_ok_{0}, bad_{0}, first_bad_{0};
};

void fill_numbered(TickRecord& r, std::uint64_t k, int body_points) {
  const double d = static_cast<double>(k);
  r.seq = k;
  r.sim_time = d;
  r.due_ns = 0;  // unpaced: no overrun watchdog (its held forces would not carry the numbers)
  r.period_ns = 0;
  r.instrument_count = 1 + static_cast<int>(k % tool::kMaxInstruments);
  r.flags = static_cast<std::uint32_t>(k & 0xff);
  r.last_tick = false;
  for (int i = 0; i < r.instrument_count; ++i) {
    InstrumentRecord& ir = r.instruments[static_cast<std::size_t>(i)];
    ir.pose.pitch = ir.pose.yaw = ir.pose.insertion = ir.pose.roll = ir.pose.jaw = d;
    ir.tip = Eigen::Vector3d(d, d, d);
    ir.force = Eigen::Vector3d(d, -d, d);
    ir.device_force = Eigen::Vector3d(d, d + i, -d);
    ir.direction = Eigen::Vector3d(-d, d, d);
    ir.flags = static_cast<std::uint32_t>(k & 0xff);
    ir.contact_points = static_cast<std::uint32_t>(k);
    ir.saturated = k % 2 == 1;
  }
  r.organ.contact_count = static_cast<int>(k % (kMaxContactEntries + 1));
  for (int l = 0; l < r.organ.contact_count; ++l) {
    ContactRecord& c = r.organ.contacts[static_cast<std::size_t>(l)];
    c.node = static_cast<int>(k);
    c.instrument = l;
    c.lambda = Eigen::Vector3d(d, d, l);
    c.u_tilde = Eigen::Vector3d(l, d, d);
  }
  r.organ.point_count = static_cast<int>(k % static_cast<std::uint64_t>(body_points + 1));
  for (int j = 0; j < 3 * r.organ.point_count; ++j) r.organ.points[j] = d + j;
}

// The paced (real-time) hand-off, the mode where the loop overwrites slots the publisher may be copying: a producer
// that never waits against a publisher writing every record it reaches. Every record written is whole (each field
// equals its tick's number, with that tick's own counts of instruments, contacts and points), none is torn, and under
// ThreadSanitizer (scripts/sanitize.sh thread) the hand-off is free of data races (before the payload moved through
// atomic words, TSan reported the publisher's copy racing with the loop's writes).
TEST(Publisher, PacedHandOffWritesWholeRecordsWhileTheLoopOverwrites) {
  constexpr int kPoints = 7;
  NumberedSink sink(kPoints);
  PublisherOptions o;
  o.slots = 4;  // the smallest ring: the loop laps the publisher often
  o.body_points = kPoints;
  Publisher p(sink, o);
  ASSERT_FALSE(p.back_pressure());
  std::uint64_t k = 0;
  for (; k < 200000 || sink.frames_ok() < 1000; ++k) {
    TickRecord& r = p.begin();
    ASSERT_EQ(r.organ.point_capacity, kPoints);
    fill_numbered(r, k, kPoints);
    p.commit();
  }
  p.finish();
  EXPECT_EQ(sink.bad(), 0u) << "first torn record: tick " << sink.first_bad() - 1;
  EXPECT_GE(sink.frames_ok(), 1000u);
  EXPECT_GE(sink.forces_ok(), 1000u);
  EXPECT_EQ(p.written() + p.skipped(), k) << "every record written or counted as skipped";
}

// The record is handed over as the bytes in use: a tick without contacts moves its header, not 64 empty entries.
TEST(Publisher, RecordBytesCoverOnlyTheContactsATickHas) {
  TickRecord r;
  r.organ.contact_count = 0;
  const std::size_t none = record_bytes(r);
  EXPECT_LT(none, sizeof(TickRecord) - kMaxContactEntries * sizeof(ContactRecord) + 1);
  r.organ.contact_count = 3;
  EXPECT_EQ(record_bytes(r), none + 3 * sizeof(ContactRecord));
  r.organ.contact_count = kMaxContactEntries + 5;  // bounded
  EXPECT_EQ(record_bytes(r), none + kMaxContactEntries * sizeof(ContactRecord));
  EXPECT_LE(record_bytes(r), sizeof(TickRecord));
}

}  // namespace
}  // namespace surgsim
