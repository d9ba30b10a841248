// surgsim-device-sim: a stand-in for a haptic device driver. Publishes ToolCommand at a fixed rate from a
// trajectory file or a scripted motion, and reads ForceFeedback back (reporting the largest force and saturations),
// so that the haptic node's live input path is exercised between real processes.
//
// --physical: a simulated 1-D device along the tool shaft (the insertion axis) closing the loop over DDS. Each tick
// (dt = 1/--rate) it integrates m x'' = F_hand - b x' + F_feedback . axis by semi-implicit Euler (v += a dt, then
// x += v dt) with the ForceFeedback that arrived last, and publishes the new insertion x; pitch, yaw, roll and jaw are
// held (the trajectory's first pose, or the flags). `axis` is the shaft direction into the body (tool_geometry of the
// scene's tool), so a positive hand force pushes the tool in and the organ's push-back is negative along it.
// At the end it reports settling time, the oscillation left over the last --window seconds (peak-to-peak of the
// position and of the force, sign changes of the velocity) and the resting force against the hand's.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <vector>

#include "surgsim_types.h"
#include "core/clock.h"
#include "dds_support.h"
#include "core/error.h"
#include "os/thread_priority.h"
#include "rt_loop.h"
#include "scene/scene.h"
#include "core/stats.h"
#include "tool/tool.h"
#include "tool/trajectory.h"

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }

using namespace surgsim;
namespace sdds = surgsim::dds;
using eprosima::fastdds::dds::DataReader;
using eprosima::fastdds::dds::SampleInfo;
using eprosima::fastrtps::types::ReturnCode_t;

class ForceListener : public eprosima::fastdds::dds::DataReaderListener {
 public:
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    msg::ForceFeedback f;
    while (reader->take_next_sample(&f, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      const double n = std::sqrt(f.force().x() * f.force().x() + f.force().y() * f.force().y() +
                                 f.force().z() * f.force().z());
      std::lock_guard<std::mutex> lock(mutex);
      ++received;
      if (!std::isfinite(n)) ++nonfinite;
      max_force = std::max(max_force, n);
      saturated += f.saturated() ? 1 : 0;
      last = Eigen::Vector3d(f.force().x(), f.force().y(), f.force().z());
      last_flags = f.flags();
      if ((f.flags() & msg::kFlagInputLost) == 0) ++used_commands;
    }
  }
  /// The force that arrived last (zero before any), its flags, and how many samples so far were computed from our
  /// commands (not flagged input-lost).
  void latest(Eigen::Vector3d& force, std::uint32_t& flags, std::uint64_t& used) {
    std::lock_guard<std::mutex> lock(mutex);
    force = last;
    flags = last_flags;
    used = used_commands;
  }
  std::mutex mutex;
  std::uint64_t received = 0, nonfinite = 0, saturated = 0, used_commands = 0;
  double max_force = 0;
  Eigen::Vector3d last = Eigen::Vector3d::Zero();
  std::uint32_t last_flags = 0;
};

// The --physical device and what it reports.
struct PhysicalDevice {
  double mass = 0.1;        // kg
  double damping = 0.5;     // N s/m
  double hand_force = 2.0;  // N along the shaft, into the body
  double window = 0.5;      // s, the final window the oscillation and the resting force are measured over
  double band = 0.0005;     // m, settling band of the position about its final value
};

struct PhysicalSample {
  double t, x, v, f_axis;  // s, m, m/s, N (feedback along the shaft; negative pushes the tool out)
  Eigen::Vector3d f;
  std::uint32_t flags;
};

nlohmann::json physical_summary(const PhysicalDevice& dev, const std::vector<PhysicalSample>& s, double dt) {
  nlohmann::json j;
  if (s.empty()) return j;
  const double t_end = s.back().t;
  const double t_window = t_end - dev.window;
  double x_sum = 0, f_sum = 0, x_min = 1e300, x_max = -1e300, f_min = 1e300, f_max = -1e300;
  int n = 0, sign_changes = 0, last_sign = 0;
  const double v_eps = 1e-3;  // m/s: below this the velocity counts as at rest (no sign)
  for (const auto& p : s) {
    if (p.t < t_window) continue;
    const double push = -p.f_axis;
    x_sum += p.x;
    f_sum += push;
    x_min = std::min(x_min, p.x);
    x_max = std::max(x_max, p.x);
    f_min = std::min(f_min, push);
    f_max = std::max(f_max, push);
    ++n;
    const int sign = p.v > v_eps ? 1 : p.v < -v_eps ? -1 : 0;
    if (sign != 0) {
      if (last_sign != 0 && sign != last_sign) ++sign_changes;
      last_sign = sign;
    }
  }
  const double x_final = x_sum / n, f_final = f_sum / n;
  // Settling time: the first time after which the position stays within `band` of its final value (its mean over
  // the window) for at least `window` s. Later excursions out of the band are counted (a disturbance: on a loaded
  // machine, a late tick of either process, whose force the node holds then fades), and the last return into the
  // band is reported too. Settled: inside the band over the whole final window.
  double settle = -1, last_exit = 0, entered = 0;
  bool inside = false;
  int exits_after = 0;
  double x_peak = -1e300, f_peak = 0;
  std::uint64_t lost = 0;
  for (const auto& p : s) {
    x_peak = std::max(x_peak, p.x);
    f_peak = std::max(f_peak, -p.f_axis);
    if ((p.flags & msg::kFlagInputLost) != 0) ++lost;
    const bool in = std::abs(p.x - x_final) <= dev.band;
    if (in && !inside) entered = p.t;
    if (!in) {
      if (inside && settle >= 0) ++exits_after;
      last_exit = p.t + dt;
    }
    inside = in;
    if (in && settle < 0 && p.t - entered >= dev.window) settle = entered;
  }
  if (settle < 0) settle = inside ? entered : t_end;
  const double ratio = dev.hand_force != 0 ? f_final / dev.hand_force : 0;
  const bool settled = last_exit <= t_window + 1e-9;
  j["mode"] = "physical";
  j["mass_kg"] = dev.mass;
  j["damping_ns_per_m"] = dev.damping;
  j["hand_force_n"] = dev.hand_force;
  j["steps"] = s.size();
  j["sim_seconds"] = t_end;
  j["window_s"] = dev.window;
  j["settle_band_m"] = dev.band;
  j["settling_time_s"] = settle;
  j["settled"] = settled;
  j["last_band_exit_s"] = last_exit;
  j["band_exits_after_settling"] = exits_after;
  j["feedback_input_lost_steps"] = lost;
  j["insertion_final_m"] = x_final;
  j["overshoot_m"] = x_peak - x_final;
  j["position_p2p_window_m"] = x_max - x_min;
  j["force_p2p_window_n"] = f_max - f_min;
  j["velocity_sign_changes_window"] = sign_changes;
  j["force_final_n"] = f_final;
  j["force_peak_n"] = f_peak;
  j["force_final_over_hand"] = ratio;
  j["force_final_error"] = std::abs(ratio - 1.0);
  return j;
}

// Scripted motion: a slow vertical oscillation of the insertion about `depth`, for trying a device by hand.
Pose5 scripted(double t, double depth) {
  Pose5 p;
  p.insertion = depth + 0.02 * std::sin(2 * M_PI * 0.5 * t);
  p.jaw = 0.4;
  return p;
}

}  // namespace

int main(int argc, char** argv) {
  std::string trajectory, stats, profiles, participant, out_csv, scene_name = "liver";
  double rate = 1000, duration = -1, depth = 0.16, start_delay = 0;
  int domain = -1, rt_priority = 0, dds_rt_priority = 20;
  double wait_for_haptic = 0;
  bool physical = false;
  PhysicalDevice dev;
  double pitch = 0, yaw = 0, roll = 0, jaw = 0.5, insertion0 = 0.155;
  CLI::App cli{"surgsim device simulator: publishes ToolCommand (5-DOF pose) like a haptic device driver, from a "
               "trajectory file or a scripted motion, and reads the ForceFeedback the haptic node sends back. "
               "--physical simulates a 1-D device along the shaft (mass, damping, a constant hand force) driven by "
               "the force fed back, closing the loop over DDS."};
  cli.add_option("--trajectory", trajectory,
                 "Trajectory file to play (default: scripted sinusoidal poke); with --physical its first pose is held");
  cli.add_option("--rate", rate, "Publication rate, Hz (--physical: also the integration rate)")->capture_default_str();
  cli.add_option("--duration", duration,
                 "Seconds to run (default: trajectory length + 0.5 s, --physical 5 s, else until SIGINT)");
  cli.add_option("--depth", depth, "Mean insertion of the scripted motion, m")->capture_default_str();
  cli.add_option("--wait-for-haptic", wait_for_haptic, "Wait up to S seconds for a haptic node to subscribe");
  cli.add_option("--stats", stats, "JSON summary on exit");
  cli.add_option("--domain", domain, "DDS domain id (default $SURGSIM_DOMAIN or 0)");
  cli.add_option("--dds-profiles", profiles, "Fast DDS XML profiles file (default config/dds/profiles.xml)");
  cli.add_option("--dds-participant", participant, "Participant profile (default $SURGSIM_DDS_PARTICIPANT or surgsim_default)");
  cli.add_option("--rt-priority", rt_priority, "SCHED_FIFO priority of the loop (0 = normal scheduling)")
      ->capture_default_str();
  cli.add_option("--dds-rt-priority", dds_rt_priority,
                 "SCHED_FIFO priority of the DDS threads, below the loop's (used with --rt-priority > 1), so a force "
                 "is taken when it arrives")
      ->capture_default_str();
  cli.add_flag("--physical", physical,
               "Simulated device: m x'' = F_hand - b x' + F_feedback . axis along the shaft, at --rate");
  cli.add_option("--mass", dev.mass, "--physical: moving mass, kg")->capture_default_str();
  cli.add_option("--damping", dev.damping, "--physical: the device's own viscous damping, N s/m")->capture_default_str();
  cli.add_option("--hand-force", dev.hand_force, "--physical: constant hand force along the shaft (into the body), N")
      ->capture_default_str();
  cli.add_option("--scene", scene_name, "--physical: scene whose tool gives the shaft axis")->capture_default_str();
  cli.add_option("--insertion", insertion0,
                 "--physical: starting insertion, m (default: the trajectory's first pose, else 0.155, the tip 5 mm "
                 "above the shipped liver)");
  cli.add_option("--pitch", pitch, "--physical: held pitch, rad (without --trajectory)")->capture_default_str();
  cli.add_option("--yaw", yaw, "--physical: held yaw, rad (without --trajectory)")->capture_default_str();
  cli.add_option("--roll", roll, "--physical: held roll, rad (without --trajectory)")->capture_default_str();
  cli.add_option("--jaw", jaw, "--physical: held jaw opening, rad (without --trajectory)")->capture_default_str();
  cli.add_option("--window", dev.window, "--physical: final window for oscillation and resting force, s")
      ->capture_default_str();
  cli.add_option("--settle-band", dev.band, "--physical: settling band of the position, m")->capture_default_str();
  cli.add_option("--out", out_csv, "--physical: per-step CSV (t, insertion, velocity, force along the shaft, force)");
  CLI11_PARSE(cli, argc, argv);
  (void)start_delay;

  try {
    if (!(rate >= 1 && rate <= 20000)) throw_error("--rate ", rate, " Hz is out of range [1, 20000]");
    Trajectory traj;
    if (!trajectory.empty()) traj = Trajectory::load(trajectory);
    if (duration < 0 && !trajectory.empty() && !physical) duration = traj.duration() + 0.5;
    if (duration < 0 && physical) duration = 5.0;
    Pose5 hold;
    Eigen::Vector3d axis = Eigen::Vector3d::Zero();
    if (physical) {
      if (!(dev.mass > 0 && std::isfinite(dev.mass))) throw_error("--mass ", dev.mass, " kg: must be > 0");
      if (!(dev.damping >= 0 && std::isfinite(dev.damping))) throw_error("--damping ", dev.damping, " N s/m: must be >= 0");
      if (!std::isfinite(dev.hand_force)) throw_error("--hand-force must be finite");
      if (!(dev.window > 0 && dev.window < duration)) throw_error("--window ", dev.window, " s: must be in (0, --duration)");
      if (!trajectory.empty()) {
        hold = traj.at(0);
        if (cli.count("--insertion") > 0) hold.insertion = insertion0;
      } else {
        hold.pitch = pitch;
        hold.yaw = yaw;
        hold.roll = roll;
        hold.jaw = jaw;
        hold.insertion = insertion0;
      }
      const Scene scene = load_scene(resolve_scene_path(scene_name));
      axis = tool_geometry(scene.tool, hold).direction;
    }

    sdds::DdsOptions o;
    o.domain = domain >= 0 ? domain : sdds::default_domain();
    o.profiles_file = profiles.empty() ? config_dir() + "/dds/profiles.xml" : profiles;
    o.participant_profile = participant;
    o.name = "surgsim_device_sim";
    // The DDS threads start at SCHED_FIFO below the loop (as in the haptic node), never at or above it.
    std::optional<ScopedFifo> dds_priority(std::in_place,
                                           rt_priority > 1 ? std::clamp(dds_rt_priority, 0, rt_priority - 1) : 0);
    sdds::Participant p(o);
    ForceListener forces;
    auto* writer = p.writer(p.topic(sdds::kToolCommandTopic, new msg::ToolCommandPubSubType()), sdds::kStreamWriter);
    p.reader(p.topic(sdds::kForceFeedbackTopic, new msg::ForceFeedbackPubSubType()), sdds::kStreamReader, &forces);
    dds_priority.reset();

    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    if (wait_for_haptic > 0) {
      const std::uint64_t until = monotonic_ns() + static_cast<std::uint64_t>(wait_for_haptic * 1e9);
      eprosima::fastdds::dds::PublicationMatchedStatus st;
      while (!g_stop && monotonic_ns() < until) {
        writer->get_publication_matched_status(st);
        if (st.current_count > 0) break;
        struct timespec ts{0, 20000000};
        nanosleep(&ts, nullptr);
      }
      std::cerr << "device_sim: " << (st.current_count > 0 ? "haptic node matched" : "no haptic node yet") << "\n";
    }

    nlohmann::json summary;
    msg::ToolCommand cmd;
    const auto send = [&](std::uint64_t seq, const Pose5& pose) {
      cmd.seq(seq);
      cmd.stamp_ns(monotonic_ns());
      cmd.pose().pitch(pose.pitch);
      cmd.pose().yaw(pose.yaw);
      cmd.pose().insertion(pose.insertion);
      cmd.pose().roll(pose.roll);
      cmd.pose().jaw(pose.jaw);
      writer->write(&cmd);
    };
    const RealtimeStatus rt = enter_realtime(rt_priority, false);
    if (rt_priority > 0) std::cerr << "device_sim: " << rt.note << "\n";
    summary["realtime"] = rt.note;
    PeriodicTimer timer(static_cast<std::int64_t>(1e9 / rate));
    timer.start();
    std::uint64_t k = 0;
    if (!physical) {
      const std::uint64_t t0 = monotonic_ns();
      for (;; ++k) {
        timer.wait();
        const double t = static_cast<double>(monotonic_ns() - t0) * 1e-9;
        if (g_stop || (duration >= 0 && t > duration)) break;
        send(k, trajectory.empty() ? scripted(t, depth) : traj.at(t));
      }
    } else {
      // Hold the start pose until the haptic node answers with a force computed from our commands (not flagged
      // input-lost), so the run starts with the loop closed; then t = 0.
      const double dt = 1.0 / rate;
      Eigen::Vector3d f;
      std::uint32_t flags = 0;
      std::uint64_t used = 0;
      const std::uint64_t until = monotonic_ns() + static_cast<std::uint64_t>(std::max(wait_for_haptic, 1.0) * 1e9);
      while (!g_stop && monotonic_ns() < until) {
        timer.wait();
        send(k++, hold);
        forces.latest(f, flags, used);
        if (used >= 10) break;
      }
      if (used < 10) throw_error("no force feedback computed from our commands (is a haptic node running with --input device?)");
      std::cerr << "device_sim: physical device, m " << dev.mass << " kg, b " << dev.damping << " N s/m, hand "
                << dev.hand_force << " N along [" << axis.transpose() << "], from insertion " << hold.insertion
                << " m, " << duration << " s at " << rate << " Hz\n";
      const auto steps = static_cast<std::size_t>(std::llround(duration * rate));
      std::vector<PhysicalSample> samples;
      samples.reserve(steps);
      double x = hold.insertion, v = 0;
      Pose5 pose = hold;
      for (std::size_t i = 0; i < steps && !g_stop; ++i) {
        timer.wait();
        forces.latest(f, flags, used);
        const double f_axis = f.dot(axis);
        const double a = (dev.hand_force - dev.damping * v + f_axis) / dev.mass;
        v += a * dt;  // semi-implicit Euler
        x += v * dt;
        pose.insertion = x;
        send(k++, pose);
        samples.push_back({static_cast<double>(i + 1) * dt, x, v, f_axis, f, flags});
      }
      summary.update(physical_summary(dev, samples, dt));
      summary["deadline_misses"] = timer.misses();
      if (!out_csv.empty()) {
        std::FILE* out = std::fopen(out_csv.c_str(), "w");
        if (out == nullptr) throw_error(out_csv, ": cannot create the --out file");
        std::fprintf(out, "t,insertion_m,velocity_m_s,force_axis_n,fx,fy,fz,flags\n");
        for (const auto& s : samples)
          std::fprintf(out, "%.4f,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%u\n", s.t, s.x, s.v, s.f_axis, s.f.x(), s.f.y(),
                       s.f.z(), s.flags);
        std::fclose(out);
      }
      std::cerr << "device_sim: settling time " << summary["settling_time_s"].get<double>() << " s ("
                << (summary["settled"].get<bool>() ? "settled" : "NOT settled") << ", "
                << summary["band_exits_after_settling"] << " excursions later, last back in the band at "
                << summary["last_band_exit_s"].get<double>() << " s), over the last " << dev.window
                << " s: position p-p " << summary["position_p2p_window_m"].get<double>() * 1e3 << " mm, force p-p "
                << summary["force_p2p_window_n"].get<double>() << " N, " << summary["velocity_sign_changes_window"]
                << " velocity sign changes; resting force " << summary["force_final_n"].get<double>() << " N against "
                << dev.hand_force << " N from the hand (" << summary["force_final_error"].get<double>() * 100
                << " % off), overshoot " << summary["overshoot_m"].get<double>() * 1e3 << " mm, peak force "
                << summary["force_peak_n"].get<double>() << " N\n";
    }
    std::lock_guard<std::mutex> lock(forces.mutex);
    std::cerr << "device_sim: " << k << " commands sent, " << forces.received << " force samples received, max |F| "
              << forces.max_force << " N, " << forces.saturated << " saturated, " << forces.nonfinite
              << " non-finite\n";
    if (!stats.empty()) {
      nlohmann::json j = summary;
      j["commands_sent"] = k;
      j["forces_received"] = forces.received;
      j["force_max_n"] = forces.max_force;
      j["saturated"] = forces.saturated;
      j["nonfinite"] = forces.nonfinite;
      write_json_file(stats, j);
    }
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "device_sim: " << e.what() << "\n";
    return 1;
  }
}
