#include "haptic_app.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <sys/resource.h>
#include <ctime>

#include "surgsim_types.h"
#include "core/clock.h"
#include "core/error.h"
#include "haptic_dds.h"
#include "compliance/tensor_cache.h"
#include "mesher/scene_mesh.h"
#include "publisher.h"
#include "os/cpu_affinity.h"
#include "os/cpu_latency.h"
#include "os/thread_priority.h"
#include "rt_loop.h"
#include "tool/tool.h"

using namespace surgsim::core;
using namespace surgsim::os;
using namespace surgsim::tool;
using namespace surgsim::compliance;
using namespace surgsim::contact;
using namespace surgsim::scene;
using namespace surgsim::mesher;

namespace surgsim {
namespace {

/// CPU time of the calling thread, ns (excludes time it was preempted, in interrupts or stolen by the hypervisor).
std::uint64_t thread_cpu_ns() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<std::uint64_t>(ts.tv_sec) * 1000000000ull + static_cast<std::uint64_t>(ts.tv_nsec);
}

}  // namespace

HapticApp::HapticApp(const HapticOptions& options)
    : options_(options), tick_us_(1), tick_cpu_us_(1), wake_late_us_(1) {
  // --- init: CPU placement. With --cpu N the loop thread runs on CPU N (run()) and every thread this node starts
  // from here on (DDS, publisher, log writers, the multirate tracker) inherits the other CPUs (os/cpu_affinity.h);
  // the model is built there too. ---
  if (options_.cpu >= 0) {
    const std::vector<int> allowed = allowed_cpus();
    if (std::find(allowed.begin(), allowed.end(), options_.cpu) == allowed.end()) {
      throw_error("--cpu ", options_.cpu, ": this process may run on CPUs ", cpu_list(allowed),
                  ": give one of them, or -1 not to pin the loop");
    }
    placement_note_ = keep_off_cpu(options_.cpu);
  } else {
    placement_note_ = "not pinned (--cpu -1)";
  }
  // --- init: scene ---
  scene_ = load_scene(resolve_scene_path(options_.scene));
  rate_hz_ = options_.rate_hz > 0 ? options_.rate_hz : scene_.haptic.rate_hz;
  if (!(rate_hz_ >= 1 && rate_hz_ <= 20000)) throw_error("--rate ", rate_hz_, " Hz is out of range [1, 20000]");
  dt_ = 1.0 / rate_hz_;
  const std::string cache = options_.cache_dir.empty() ? default_cache_dir() : options_.cache_dir;
  std::ostream* progress = options_.quiet ? nullptr : &std::cerr;

  // --- init: tool input ---
  if (options_.input != "replay" && options_.input != "device") {
    throw_error("--input '", options_.input, "' is not an input (use replay or device)");
  }
  live_ = options_.input == "device";
  instrument_count_ = static_cast<int>(scene_.tools.size());
  std::string replay;
  if (!live_) {
    replay = options_.replay.empty() ? scene_.trajectory : options_.replay;
    if (replay.empty()) throw_error(scene_.file, ": no trajectory to replay (give --replay FILE or set 'trajectory')");
    trajectory_ = MultiTrajectory::load(replay);
    // Each instrument replays the column group of its name (a one-instrument file drives a one-instrument scene
    // whatever its name).
    std::string names;
    for (const ToolSpec& t : scene_.tools) names += (names.empty() ? "" : ", ") + t.name;
    std::string file_names;
    for (const std::string& n : trajectory_.names()) file_names += (file_names.empty() ? "" : ", ") + n;
    for (int i = 0; i < instrument_count_; ++i) {
      Instrument& in = instruments_[static_cast<std::size_t>(i)];
      in.track = instrument_count_ == 1 && trajectory_.instruments() == 1
                     ? 0 : trajectory_.find(scene_.tools[static_cast<std::size_t>(i)].name);
      if (in.track < 0) {
        throw_error(replay, ": has no instrument '", scene_.tools[static_cast<std::size_t>(i)].name, "' (it has ",
                    file_names, "; the scene ", scene_.file, " has ", names,
                    "): record one with --record, or give a trajectory with a column group per instrument");
      }
      Pose5 first;
      if (trajectory_.at(in.track, 0, first)) in.held_pose = first;
    }
    if (trajectory_.instruments() > instrument_count_) {
      throw_error(replay, ": has ", trajectory_.instruments(), " instruments (", file_names, ") but the scene ",
                  scene_.file, " has ", instrument_count_, " (", names, "): give the scene with every instrument");
    }
  }
  double duration = options_.duration;
  if (duration < 0) duration = live_ ? 3600.0 : trajectory_.duration() + 0.5;
  total_ticks_ = static_cast<std::uint64_t>(std::llround(duration * rate_hz_));
  if (total_ticks_ == 0) total_ticks_ = 1;

  // --- init: the organ the scene names (a liver builds its mesh, tensors, contacts and bucket grid; the intestine
  // its mass-spring body and nothing of the liver) ---
  organ_ = make_haptic_organ(scene_, cache, total_ticks_, progress, OrganBuildOptions{options_.tracker_threads, options_.speed <= 0});
  if (!options_.tick_trace.empty()) organ_->time_stages(true);
  scene_hash_ = scene_.hash() ^ (organ_->mesh_hash() * 0x9E3779B97F4A7C15ull);
  for (int i = 0; i < instrument_count_; ++i) {
    instruments_[static_cast<std::size_t>(i)].force_stage =
        ForceStage(scene_.haptic, scene_.tools[static_cast<std::size_t>(i)].force_limit);
  }

  // --- init: outputs ---
  if (!options_.record.empty()) {
    std::vector<std::string> names;
    for (const ToolSpec& t : scene_.tools) names.push_back(t.name);
    recorder_.open(options_.record, names);  // v1 for one instrument named "tool", else v2
    record_writer_ = std::make_unique<AsyncLineWriter>(recorder_.file(), options_.speed <= 0, std::size_t{1} << 14,
                                                       TrajectoryRecorder::kMultiLineBytes);
  }
  if (!options_.log.empty()) {
    log_ = std::fopen(options_.log.c_str(), "w");
    if (log_ == nullptr) throw_error(options_.log, ": cannot create the --log file");
    std::setvbuf(log_, nullptr, _IOFBF, 1 << 16);
    // tick, t, instrument 0's force sent, all contacts; with several instruments each one's force and contacts follow.
    std::fprintf(log_, "tick,t,fx,fy,fz,contacts");
    if (instrument_count_ > 1) {
      for (const ToolSpec& tool : scene_.tools) {
        const char* n = tool.name.c_str();
        std::fprintf(log_, ",%s.fx,%s.fy,%s.fz,%s.contacts", n, n, n, n);
      }
    }
    std::fprintf(log_, "\n");
    std::fflush(log_);
    log_writer_ = std::make_unique<AsyncLineWriter>(log_, options_.speed <= 0, std::size_t{1} << 14, 1024);
  }
  tick_us_ = SampleRecorder(total_ticks_ + 16);
  tick_cpu_us_ = SampleRecorder(total_ticks_ + 16);
  if (!options_.tick_trace.empty()) {
    tick_trace_file_ = std::fopen(options_.tick_trace.c_str(), "w");
    if (tick_trace_file_ == nullptr) throw_error(options_.tick_trace, ": cannot create the --tick-trace file");
    tick_trace_.resize(static_cast<std::size_t>(total_ticks_));
  }
  wake_late_us_ = SampleRecorder(total_ticks_ + 16);

  // --- init: DDS entities (QoS from the XML profiles) ---
  // Their threads start at SCHED_FIFO below the loop's priority (thread_priority.h): a device command or a visual
  // status is taken the moment it arrives, and never delays the loop.
  // Never at or above the loop: with a normally scheduled loop (--rt-priority 0) or --speed max, they stay normal too.
  const int dds_priority_value = options_.speed > 0 && options_.rt_priority > 1
                                     ? std::min(options_.dds_rt_priority, options_.rt_priority - 1) : 0;
  std::optional<ScopedFifo> dds_priority(std::in_place, dds_priority_value);
  dds_threads_note_ = dds_priority->note();
  dds::DdsOptions dopt;
  dopt.domain = options_.domain >= 0 ? options_.domain : dds::default_domain();
  dopt.profiles_file = options_.dds_profiles.empty() ? config_dir() + "/dds/profiles.xml" : options_.dds_profiles;
  dopt.participant_profile = options_.dds_participant;
  dopt.name = "surgsim_haptic";
  dds_ = std::make_unique<HapticDds>(dopt, live_, scene_hash_, instrument_count_);
  if (!options_.quiet)
    std::cerr << "haptic_node: DDS " << dds_->profile() << ": " << dds_->description() << "; DDS threads "
              << dds_threads_note_ << "\n";
  organ_->create_writers(dds_->participant(), scene_hash_);  // e.g. the intestine's BodyState, every tick
  dds_->attach_organ(organ_.get());
  // The publisher thread starts here, so it runs at the DDS threads' priority (below the loop). --speed max keeps
  // every tick's frame (the producer waits when the ring is full); a paced run never waits (publisher.h).
  PublisherOptions popt;
  popt.body_points = organ_->output_points();
  popt.lossless = options_.speed <= 0;
  popt.samples = static_cast<std::size_t>(total_ticks_) + 16;
  // haptic.publish_hz: ContactFrame and the organ's topics for one tick in this many (ForceFeedback every tick).
  if (scene_.haptic.publish_hz > 0) {
    popt.frame_every = static_cast<std::uint64_t>(std::max(1.0, std::round(rate_hz_ / scene_.haptic.publish_hz)));
  }
  // SURGSIM_HAPTIC_PUBLISHER=inline: the writes on the loop thread as before the publisher thread existed, to
  // measure against (stats publisher_mode "inline (loop thread)"); anything else: the publisher thread.
  const char* pub_env = std::getenv("SURGSIM_HAPTIC_PUBLISHER");
  popt.inline_writes = pub_env != nullptr && std::string(pub_env) == "inline";
  publisher_ = std::make_unique<Publisher>(*dds_, popt);
  dds_priority.reset();

  msg::SceneInfo info;
  info.scene_name(scene_.name);
  info.scene_hash(scene_hash_);
  info.mesh_hash(organ_->mesh_hash());
  info.material_hash(material_hash(scene_.material));
  info.tensor_hash(organ_->tensor_hash());
  info.node_count(organ_->node_count());
  info.surface_node_count(organ_->surface_node_count());
  info.instrument_count(static_cast<std::uint32_t>(instrument_count_));
  info.haptic_rate_hz(rate_hz_);
  info.visual_rate_hz(scene_.visual.rate_hz);
  info.start_stamp_ns(monotonic_ns());
  fill_scene_organs(organ_->identities(), scene_.name, info);  // one OrganInfo per organ (the whole scene above)
  dds_->publish_scene_info(info);

  if (!options_.quiet) {
    std::cerr << "haptic_node: scene '" << scene_.name << "' (" << scene_.file << "), " << organ_->describe()
              << instrument_count_ << (instrument_count_ == 1 ? " instrument, " : " instruments, ") << rate_hz_
              << " Hz for " << total_ticks_ << " ticks; "
              << (live_ ? std::string("live input from the device topic") : "replaying " + replay) << "\n";
  }
}

HapticApp::~HapticApp() {
  if (publisher_ != nullptr) publisher_->finish();  // before the DDS entities it writes to go
  // The writer threads drain into the files, so they stop before the files close.
  record_writer_.reset();
  log_writer_.reset();
  if (log_ != nullptr) std::fclose(log_);
  if (tick_trace_file_ != nullptr) std::fclose(tick_trace_file_);
}

bool HapticApp::input_pose(int i, double t, Pose5& pose) {
  Instrument& in = instruments_[static_cast<std::size_t>(i)];
  if (!live_) {
    if (trajectory_.at(in.track, t, pose)) return true;
    pose = in.held_pose;  // recorded lost: held, as live
    return false;
  }
  dds_->latest_command(i, in.last_command, in.last_command_ns, in.commands_received);
  const bool fresh = in.commands_received > 0 &&
                     static_cast<double>(monotonic_ns() - in.last_command_ns) * 1e-9 <= options_.input_timeout;
  pose = fresh ? in.last_command : in.held_pose;
  return fresh;
}

void HapticApp::tick(std::uint64_t k) {
  const double t = static_cast<double>(k) * dt_;
  const int n = instrument_count_;

  // --- input, per instrument: a lost one drops its contacts, gets zero force and is held where it was ---
  std::array<Pose5, kMaxInstruments> pose;
  std::array<bool, kMaxInstruments> input_ok{};
  std::array<ToolGeometry, kMaxInstruments> tool;
  std::array<InstrumentInput, kMaxInstruments> inputs;
  bool any_lost = false;
  for (int i = 0; i < n; ++i) {
    const auto si = static_cast<std::size_t>(i);
    input_ok[si] = input_pose(i, t, pose[si]);
    tool[si] = tool_geometry(scene_.tools[si], pose[si]);
    inputs[si] = InstrumentInput{input_ok[si] ? &tool[si] : nullptr, pose[si].jaw};
    if (input_ok[si]) {
      instruments_[si].held_pose = pose[si];
    } else {
      any_lost = true;
    }
  }
  if (record_writer_ != nullptr && (n > 1 || input_ok[0])) {  // one instrument: its lost ticks are not recorded
    if (char* line = record_writer_->begin_line()) {
      const int len = recorder_.format_multi(line, record_writer_->slot_bytes(), t, pose.data(), input_ok.data(), n);
      if (len > 0) record_writer_->commit_line(static_cast<std::size_t>(len));
    }
  }
  if (any_lost) ++input_lost_ticks_;

  // --- every instrument's contacts in one solve (the organ couples them), then each one's force stage ---
  std::array<ContactTick, kMaxInstruments> result;
  std::array<int, kMaxInstruments> contacts_of{};  // each instrument's contacts this tick (stats and log)
  organ_->step(inputs.data(), n, dt_, result.data());

  // --- hand-off: the publisher thread writes each force (devices), the contact frame (visual node), organ topics ---
  TickRecord& out = publisher_->begin();
  out.seq = k;
  out.sim_time = t;
  out.due_ns = tick_due_ns_;
  out.period_ns = period_ns_;
  out.instrument_count = n;
  out.flags = 0;
  out.last_tick = k + 1 >= total_ticks_;
  for (int i = 0; i < n; ++i) {
    const auto si = static_cast<std::size_t>(i);
    Instrument& in = instruments_[si];
    ContactTick& r = result[si];
    in.force_stage.apply(input_ok[si] ? &tool[si] : nullptr, dt_, r);  // coupling damper + passivity (force_stage.h)
    std::uint32_t flags = 0;
    if (!input_ok[si]) {
      ++in.input_lost_ticks;
      flags |= msg::kFlagInputLost;
    }
    if (r.nonfinite) {
      ++in.nonfinite_rejected;
      flags |= msg::kFlagNonFiniteHeld;
    }
    if (r.over_capacity) {
      ++in.over_capacity_events;
      flags |= msg::kFlagOverCapacity;
    }
    if (r.saturated) {
      ++in.saturated_ticks;
      flags |= msg::kFlagSaturated;
    }
    if (r.grasp) flags |= msg::kFlagGrasp;
    InstrumentRecord& ir = out.instruments[si];
    ir.pose = pose[si];
    ir.tip = tool[si].tip;
    ir.force = r.force;
    ir.device_force = r.device_force;
    ir.direction = r.direction;
    ir.flags = flags;
    ir.contact_points = static_cast<std::uint32_t>(r.points_in_contact);
    ir.saturated = r.saturated;
    out.flags |= flags;
    const int c = contacts_of[si] = organ_->instrument_contacts(i);
    in.contacts_max = std::max(in.contacts_max, c);
    if (c > 0) ++in.contact_ticks;
    in.force_max_n = std::max(in.force_max_n, r.device_force.norm());
    force_max_n_ = std::max(force_max_n_, in.force_max_n);
  }
  organ_->fill_outputs(out.organ);
  publisher_->commit();

  // --- log and statistics ---
  const int contacts = organ_->contacts();
  if (log_writer_ != nullptr) {
    if (char* line = log_writer_->begin_line()) {
      // Numbers as the shortest text that reads back to the same double (std::to_chars: about ten times cheaper on
      // the loop thread than printf's %.17g, and bit-exact on reload); t with 9 decimals as before.
      char* p = line;
      char* const end = line + log_writer_->slot_bytes() - 1;  // room for the newline
      bool ok = true;
      const auto put = [&](auto value) {
        if (!ok) return;
        const auto r = std::to_chars(p, end, value);
        ok = r.ec == std::errc() && r.ptr < end;
        if (ok) {
          p = r.ptr;
          *p++ = ',';
        }
      };
      const auto put_vec = [&](const Eigen::Vector3d& v) {
        put(v.x());
        put(v.y());
        put(v.z());
      };
      put(static_cast<unsigned long long>(k));
      if (ok) {
        const auto r = std::to_chars(p, end, t, std::chars_format::fixed, 9);
        ok = r.ec == std::errc() && r.ptr < end;
        if (ok) {
          p = r.ptr;
          *p++ = ',';
        }
      }
      put_vec(result[0].device_force);
      put(contacts);
      for (int i = 0; n > 1 && i < n; ++i) {
        put_vec(result[static_cast<std::size_t>(i)].device_force);
        put(contacts_of[static_cast<std::size_t>(i)]);
      }
      if (ok) {
        p[-1] = '\n';  // the last field's comma
        log_writer_->commit_line(static_cast<std::size_t>(p - line));
      }
    }
  }
  if (contacts > contacts_max_) contacts_max_ = contacts;
  if (contacts > 0) ++contact_ticks_;
}

int HapticApp::run() {
  // Optionally wait until a visual node has matched our contact writer (so a demo does not lose its start).
  if (options_.wait_for_visual > 0) dds_->wait_for_reader(options_.wait_for_visual, stop_requested_);

  const RealtimeStatus rt = enter_realtime(options_.speed > 0 ? options_.rt_priority : 0, options_.lock_memory, options_.cpu);
  realtime_note_ = rt.note;
  // Idle CPUs poll instead of halting while the paced loop runs (os/cpu_latency.h): a halted virtual CPU wakes for
  // the loop's timer only once the hypervisor runs it again. Withdrawn when run() returns.
  const CpuLatencyRequest latency(options_.speed > 0 ? options_.cpu_latency_us : -1);
  cpu_latency_note_ = latency.note();
  // A loop without SCHED_FIFO keeps every frame (the publisher may make it wait when 64 ticks behind); a real-time
  // loop never waits and the publisher skips frames it reaches too late (publisher.h).
  publisher_->set_back_pressure(!rt.fifo);
  if (!options_.quiet) {
    std::cerr << "haptic_node: " << rt.note << "; " << placement_note_ << "; " << cpu_latency_note_ << "\n";
  }

  // --- run: the loop (no allocation from here to the end of the loop) ---
  rusage usage_before{};
  getrusage(RUSAGE_THREAD, &usage_before);

  const bool paced = options_.speed > 0;
  const auto period_ns = static_cast<std::int64_t>(std::llround(1e9 * dt_ / (paced ? options_.speed : 1.0)));
  PeriodicTimer timer(period_ns);
  timer.start();
  const std::uint64_t wall_start = monotonic_ns();
  loop_start_ns_ = wall_start;
  period_ns_ = paced ? static_cast<std::uint64_t>(period_ns) : 0;
  for (std::uint64_t k = 0; k < total_ticks_; ++k) {
    if (stop_requested_.load(std::memory_order_relaxed)) break;
    std::int64_t late_ns = 0;
    if (paced) {
      late_ns = timer.wait();
      wake_late_us_.add(static_cast<double>(late_ns) * 1e-3);
      tick_due_ns_ = static_cast<std::uint64_t>(timer.next_deadline_ns() - period_ns);  // this tick's deadline
    }
    const std::uint64_t t0 = monotonic_ns();
    const std::uint64_t c0 = thread_cpu_ns();
    tick(k);
    // The tick's wall time and the CPU time the loop thread got during it: the difference is time the thread was
    // off its CPU (preempted, interrupts) or waiting in the kernel; time the hypervisor took from this virtual CPU
    // counts as CPU time here.
    const std::uint64_t c1 = thread_cpu_ns();
    const std::uint64_t t1 = monotonic_ns();
    tick_cpu_us_.add(static_cast<double>(c1 - c0) * 1e-3);
    tick_us_.add(static_cast<double>(t1 - t0) * 1e-3);
    if (k < tick_trace_.size()) {
      // Unpaced, a tick has no deadline: its start stands for it.
      tick_trace_[k] =
          tick_trace_row((paced ? tick_due_ns_ : t0) - loop_start_ns_, late_ns, t1 - t0, c1 - c0, timer.misses());
      if (const contact::ContactStageTimes* st = organ_->stage_times()) tick_trace_[k].stage_ns = st->ns;
    }
    ticks_done_ = k + 1;
  }
  wall_seconds_ = static_cast<double>(monotonic_ns() - wall_start) * 1e-9;
  rusage usage_after{};
  getrusage(RUSAGE_THREAD, &usage_after);
  loop_involuntary_switches_ = usage_after.ru_nivcsw - usage_before.ru_nivcsw;
  loop_voluntary_switches_ = usage_after.ru_nvcsw - usage_before.ru_nvcsw;
  loop_page_faults_ = (usage_after.ru_minflt - usage_before.ru_minflt) + (usage_after.ru_majflt - usage_before.ru_majflt);
  if (options_.cpu >= 0) other_threads_on_loop_cpu_ = other_threads_allowed_on(options_.cpu);
  deadline_misses_ = paced ? timer.misses() : 0;
  // The last tick's force and frame are written, then a zero force releases the device.
  finish_publishing();
  // --- shutdown starts here: the writer threads drain every line before the files close ---
  for (auto* w : {record_writer_.get(), log_writer_.get()}) {
    if (w != nullptr) w->finish();
  }
  record_writer_stats_ = record_writer_ ? record_writer_->dropped() + record_writer_->write_errors() : 0;
  log_writer_stats_ = log_writer_ ? log_writer_->dropped() + log_writer_->write_errors() : 0;
  record_writer_.reset();
  log_writer_.reset();
  recorder_.close();
  if (log_ != nullptr) std::fflush(log_);
  write_tick_trace();
  return 0;
}

void HapticApp::write_tick_trace() {
  if (tick_trace_file_ == nullptr) return;
  surgsim::write_tick_trace(tick_trace_file_, tick_trace_.data(),
                            static_cast<std::size_t>(std::min<std::uint64_t>(ticks_done_, tick_trace_.size())));
  std::fclose(tick_trace_file_);
  tick_trace_file_ = nullptr;
}

void HapticApp::finish_publishing() {
  if (publisher_ != nullptr) publisher_->finish();
}

void HapticApp::shutdown() {
  finish_publishing();
  const Percentiles tick = tick_us_.summary();
  const Percentiles late = wake_late_us_.summary();
  const Percentiles rtt = dds_->round_trip();
  const double achieved = wall_seconds_ > 0 ? static_cast<double>(ticks_done_) / wall_seconds_ : 0.0;
  nlohmann::json j;
  j["node"] = "haptic";
  j["scene"] = scene_.name;
  j["rate_hz"] = rate_hz_;
  j["speed"] = options_.speed > 0 ? nlohmann::json(options_.speed) : nlohmann::json("max");
  j["ticks"] = ticks_done_;
  j["sim_seconds"] = static_cast<double>(ticks_done_) * dt_;
  j["wall_seconds"] = wall_seconds_;
  j["achieved_hz"] = achieved;
  j["tick_us"] = to_json(tick);
  j["tick_cpu_us"] = to_json(tick_cpu_us_.summary());
  // Where the loop ran and what took its CPU away (os/cpu_affinity.h): the loop's CPU (-1: not pinned), where the
  // other threads went, how many of them may still run on the loop's CPU, and the loop thread's context switches
  // (involuntary: preempted) and page faults during the loop.
  j["cpu_placement"] = {{"loop_cpu", options_.cpu},
                        {"others", placement_note_},
                        {"other_threads_on_loop_cpu", other_threads_on_loop_cpu_}};
  j["cpu_latency"] = cpu_latency_note_;
  j["loop_involuntary_switches"] = loop_involuntary_switches_;
  j["loop_voluntary_switches"] = loop_voluntary_switches_;
  j["loop_page_faults"] = loop_page_faults_;
  j["wake_late_us"] = to_json(late);
  j["deadline_misses"] = deadline_misses_;
  j["contacts_max"] = contacts_max_;
  j["force_max_n"] = force_max_n_;
  // Totals over the instruments (instrument-ticks; one instrument: ticks).
  std::uint64_t nonfinite_rejected = 0, over_capacity_events = 0, saturated_ticks = 0;
  for (int i = 0; i < instrument_count_; ++i) {
    const Instrument& in = instruments_[static_cast<std::size_t>(i)];
    nonfinite_rejected += in.nonfinite_rejected;
    over_capacity_events += in.over_capacity_events;
    saturated_ticks += in.saturated_ticks;
  }
  j["nonfinite_rejected"] = nonfinite_rejected;
  j["over_capacity_events"] = over_capacity_events;
  j["saturated_ticks"] = saturated_ticks;
  j["contact_ticks"] = contact_ticks_;
  j["input"] = live_ ? "device" : "replay";
  j["input_lost_ticks"] = input_lost_ticks_;
  std::uint64_t commands = 0;
  for (int i = 0; i < instrument_count_; ++i) commands += instruments_[static_cast<std::size_t>(i)].commands_received;
  j["commands_received"] = commands;
  j["tensor_hash"] = std::to_string(organ_->tensor_hash());
  j["nonlinear_law"] = organ_->nonlinear_law();
  j["round_trip_us"] = to_json(rtt);
  j["visual_status_received"] = dds_->visual_status_received();
  j["realtime"] = realtime_note_;
  j["scene_hash"] = std::to_string(scene_hash_);
  j["record_write_errors"] = recorder_.write_errors();
  j["record_lines_lost"] = record_writer_stats_;
  j["log_lines_lost"] = log_writer_stats_;
  j["dds_participant"] = dds_->profile();
  j["dds_threads"] = dds_threads_note_;
  j["loop_start_ns"] = loop_start_ns_;
  // The publisher thread (publisher.h): frames written / skipped (a publisher too far behind jumps to the newest),
  // forces written / superseded by a newer one before they went out, time per record and from hand-off to force.
  j["publisher_mode"] = publisher_->inline_writes()   ? "inline (loop thread)"
                        : publisher_->lossless()        ? "every tick"
                        : publisher_->back_pressure() ? "newest force, every frame (loop waits when 64 behind)"
                                                      : "newest force, frames in order unless 32 behind";
  j["publisher_written"] = publisher_->written();
  j["publisher_thinned"] = publisher_->thinned();  // frames not written by design (haptic.publish_hz)
  j["publisher_skipped"] = publisher_->skipped();
  j["publisher_forces_written"] = publisher_->forces_written();
  j["publisher_forces_skipped"] = publisher_->forces_skipped();
  j["publisher_write_us"] = to_json(publisher_->write_us());
  j["publisher_force_latency_us"] = to_json(publisher_->force_latency_us());
  // Overrun policy: held forces sent while the loop was late (hold one period, then linear fade to zero in 10 ms),
  // fades that reached zero, and the zero force sent at exit.
  j["overrun_hold_ticks"] = publisher_->overrun_hold_ticks();
  j["overrun_faded_to_zero"] = publisher_->overrun_faded_to_zero();
  j["overrun_fade_ms"] = publisher_->fade_ms();
  j["final_zero_force_sent"] = publisher_->final_zero_sent();
  // Which organ model this run built (a liver run builds no intestine objects, an intestine run no liver ones).
  j["model_built"] = organ_->model_name();
  // "force_stage": instrument 0's energy observed, dissipated by the controller, ticks it acted.
  instruments_[0].force_stage.add_stats(j);
  // Per instrument (a scene may have several), besides the totals above.
  nlohmann::json tools = nlohmann::json::array();
  for (int i = 0; i < instrument_count_; ++i) {
    const Instrument& in = instruments_[static_cast<std::size_t>(i)];
    nlohmann::json e;
    e["name"] = scene_.tools[static_cast<std::size_t>(i)].name;
    e["contacts_max"] = in.contacts_max;
    e["force_max_n"] = in.force_max_n;
    e["input_lost_ticks"] = in.input_lost_ticks;
    e["saturated_ticks"] = in.saturated_ticks;
    e["contact_ticks"] = in.contact_ticks;
    e["over_capacity_events"] = in.over_capacity_events;
    e["nonfinite_rejected"] = in.nonfinite_rejected;
    e["commands_received"] = in.commands_received;
    e["force_stage"] = in.force_stage.to_json();
    tools.push_back(e);
  }
  j["tools"] = tools;
  j["instrument_count"] = instrument_count_;
  organ_->add_stats(j);
  if (!options_.stats.empty()) write_json_file(options_.stats, j);
  if (!options_.quiet) {
    std::cerr << "haptic_node: " << ticks_done_ << " ticks at " << achieved << " Hz (target "
              << rate_hz_ * (options_.speed > 0 ? options_.speed : 0) << "), tick p50 " << tick.p50 << " us p99 "
              << tick.p99 << " us, " << deadline_misses_ << " missed deadlines, contacts max " << contacts_max_
              << ", force max " << force_max_n_ << " N, round trip p50 " << rtt.p50
              << " us (" << rtt.count << " echoes); publisher " << publisher_->written() << " frames written, "
              << publisher_->skipped() << " skipped, " << publisher_->overrun_hold_ticks() << " held forces\n";
    organ_->print_summary(std::cerr);
  }
}

}  // namespace surgsim
