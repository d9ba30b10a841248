// surgsim-device-sim: a stand-in for a haptic device driver. Publishes ToolCommand at a fixed rate from a
// trajectory file or a scripted motion, and reads ForceFeedback back (reporting the largest force and saturations),
// so that the haptic node's live input path is exercised between real processes.
#include <CLI/CLI.hpp>
#include <atomic>
#include <cmath>
#include <csignal>
#include <iostream>
#include <mutex>
#include <nlohmann/json.hpp>

#include "Surgsim.h"
#include "SurgsimPubSubTypes.h"
#include "core/clock.h"
#include "dds_support.h"
#include "core/error.h"
#include "rt_loop.h"
#include "scene/scene.h"
#include "core/stats.h"
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
    }
  }
  std::mutex mutex;
  std::uint64_t received = 0, nonfinite = 0, saturated = 0;
  double max_force = 0;
};

// Scripted motion: a slow vertical oscillation of the insertion about `depth`, for trying a device by hand.
Pose5 scripted(double t, double depth) {
  Pose5 p;
  p.insertion = depth + 0.02 * std::sin(2 * M_PI * 0.5 * t);
  p.jaw = 0.4;
  return p;
}

}  // namespace

int main(int argc, char** argv) {
  std::string trajectory, stats, profiles, participant;
  double rate = 1000, duration = -1, depth = 0.16, start_delay = 0;
  int domain = -1;
  double wait_for_haptic = 0;
  CLI::App cli{"surgsim device simulator: publishes ToolCommand (5-DOF pose) like a haptic device driver, from a "
               "trajectory file or a scripted motion, and reads the ForceFeedback the haptic node sends back."};
  cli.add_option("--trajectory", trajectory, "Trajectory file to play (default: scripted sinusoidal poke)");
  cli.add_option("--rate", rate, "Publication rate, Hz")->capture_default_str();
  cli.add_option("--duration", duration, "Seconds to run (default: trajectory length + 0.5 s, or until SIGINT)");
  cli.add_option("--depth", depth, "Mean insertion of the scripted motion, m")->capture_default_str();
  cli.add_option("--wait-for-haptic", wait_for_haptic, "Wait up to S seconds for a haptic node to subscribe");
  cli.add_option("--stats", stats, "JSON summary on exit");
  cli.add_option("--domain", domain, "DDS domain id (default $SURGSIM_DOMAIN or 0)");
  cli.add_option("--dds-profiles", profiles, "Fast DDS XML profiles file (default config/dds/profiles.xml)");
  cli.add_option("--dds-participant", participant, "Participant profile (default $SURGSIM_DDS_PARTICIPANT or surgsim_default)");
  CLI11_PARSE(cli, argc, argv);
  (void)start_delay;

  try {
    if (!(rate >= 1 && rate <= 20000)) throw_error("--rate ", rate, " Hz is out of range [1, 20000]");
    Trajectory traj;
    if (!trajectory.empty()) traj = Trajectory::load(trajectory);
    if (duration < 0 && !trajectory.empty()) duration = traj.duration() + 0.5;

    sdds::DdsOptions o;
    o.domain = domain >= 0 ? domain : sdds::default_domain();
    o.profiles_file = profiles.empty() ? config_dir() + "/dds/profiles.xml" : profiles;
    o.participant_profile = participant;
    o.name = "surgsim_device_sim";
    sdds::Participant p(o);
    ForceListener forces;
    auto* writer = p.writer(p.topic(sdds::kToolCommandTopic, new msg::ToolCommandPubSubType()), sdds::kStreamWriter);
    p.reader(p.topic(sdds::kForceFeedbackTopic, new msg::ForceFeedbackPubSubType()), sdds::kStreamReader, &forces);

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

    PeriodicTimer timer(static_cast<std::int64_t>(1e9 / rate));
    timer.start();
    msg::ToolCommand cmd;
    std::uint64_t k = 0;
    const std::uint64_t t0 = monotonic_ns();
    for (;; ++k) {
      timer.wait();
      const double t = static_cast<double>(monotonic_ns() - t0) * 1e-9;
      if (g_stop || (duration >= 0 && t > duration)) break;
      const Pose5 pose = trajectory.empty() ? scripted(t, depth) : traj.at(t);
      cmd.seq(k);
      cmd.stamp_ns(monotonic_ns());
      cmd.pose().pitch(pose.pitch);
      cmd.pose().yaw(pose.yaw);
      cmd.pose().insertion(pose.insertion);
      cmd.pose().roll(pose.roll);
      cmd.pose().jaw(pose.jaw);
      writer->write(&cmd);
    }
    std::lock_guard<std::mutex> lock(forces.mutex);
    std::cerr << "device_sim: " << k << " commands sent, " << forces.received << " force samples received, max |F| "
              << forces.max_force << " N, " << forces.saturated << " saturated, " << forces.nonfinite
              << " non-finite\n";
    if (!stats.empty()) {
      nlohmann::json j;
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
