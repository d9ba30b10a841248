// surgsim-device-sim: a stand-in for the haptic devices of every instrument of a scene (one device per
// instrument). Publishes one ToolCommand per instrument per tick at a fixed rate (the DDS key `instrument` is the
// index in the scene's tools list) from a trajectory file or a scripted motion, and reads ForceFeedback back, per
// instrument (received, largest force, saturations, non-finite, last force), so that the haptic node's live input
// path is exercised between real processes.
//
// Trajectory: a v1 file (one instrument) drives the single tool of a one-tool scene; a v2 file names its column
// groups by the scene's tool names and each group drives the tool of that name. Where the file says an instrument's
// input was lost (five empty fields), nothing is published for it, so the haptic node times it out as the live run
// did. --silence NAME[:FROM[:TO]] stops publishing for one instrument over a time span (its device unplugged).
//
// --physical: one simulated 1-D device per instrument along its own shaft (the insertion axis), each closing its loop
// over DDS with ITS instrument's ForceFeedback. Each tick (dt = 1/--rate) every device integrates
// m x'' = F_hand - b x' + F_feedback . axis by semi-implicit Euler (v += a dt, then x += v dt) with its instrument's
// force that arrived last, and publishes the new insertion x; pitch, yaw, roll and jaw are held (the trajectory's
// first pose of that instrument, or the flags). `axis` is that instrument's shaft direction into the body
// (tool_geometry of its ToolSpec), so a positive hand force pushes the tool in and the organ's push-back is negative
// along it. The device's travel ends at insertion 0 and at the tool's shaft length (an end stop: the velocity is
// zeroed there, counted in end_stop_steps), so a tool that slips off or through the organ stops instead of running
// away. Mass, damping, hand force and the held pose take one value for every instrument or a comma list, one per
// instrument in the scene's order. At the end it reports per device the settling time, the oscillation left over the
// last --window seconds (peak-to-peak of the position and of the force, sign changes of the velocity) and the
// resting force against the hand's.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <limits>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <vector>

#include "surgsim_types.h"
#include "core/clock.h"
#include "core/error.h"
#include "core/stats.h"
#include "core/text.h"
#include "dds_support.h"
#include "os/thread_priority.h"
#include "rt_loop.h"
#include "scene/scene.h"
#include "tool/tool.h"
#include "tool/trajectory.h"

using namespace surgsim::core;
using namespace surgsim::os;
using namespace surgsim::tool;
using namespace surgsim::scene;

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }

using namespace surgsim;
namespace sdds = surgsim::dds;
using eprosima::fastdds::dds::DataReader;
using eprosima::fastdds::dds::SampleInfo;
using eprosima::fastrtps::types::ReturnCode_t;

// "a, b, c"
std::string join(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

// What came back on one instrument's ForceFeedback instance.
struct FeedbackStats {
  std::uint64_t received = 0, nonfinite = 0, saturated = 0;
  std::uint64_t used_commands = 0;  // computed from our commands (not flagged input-lost)
  std::uint64_t input_lost = 0;     // flagged input-lost by the haptic node
  double max_force = 0;             // N
  Eigen::Vector3d last = Eigen::Vector3d::Zero();
  std::uint32_t last_flags = 0;
};

class ForceListener : public eprosima::fastdds::dds::DataReaderListener {
 public:
  explicit ForceListener(int instruments) : per(static_cast<std::size_t>(instruments)) {}
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    msg::ForceFeedback f;
    while (reader->take_next_sample(&f, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      const double n = std::sqrt(f.force().x() * f.force().x() + f.force().y() * f.force().y() +
                                 f.force().z() * f.force().z());
      std::lock_guard<std::mutex> lock(mutex);
      add(total, f, n);
      if (f.instrument() < per.size())
        add(per[f.instrument()], f, n);
      else
        ++unknown_instrument;  // not an instrument of our scene (another scene's node on this domain?)
    }
  }
  /// Instrument i's force that arrived last (zero before any), its flags, and how many of its samples so far were
  /// computed from our commands (not flagged input-lost).
  void latest(std::size_t i, Eigen::Vector3d& force, std::uint32_t& flags, std::uint64_t& used) {
    std::lock_guard<std::mutex> lock(mutex);
    force = per[i].last;
    flags = per[i].last_flags;
    used = per[i].used_commands;
  }
  std::mutex mutex;
  FeedbackStats total;               // every sample, whatever its instrument
  std::vector<FeedbackStats> per;    // by instrument (index in the scene's tools list)
  std::uint64_t unknown_instrument = 0;

 private:
  static void add(FeedbackStats& s, const msg::ForceFeedback& f, double norm) {
    ++s.received;
    if (!std::isfinite(norm)) ++s.nonfinite;
    s.max_force = std::max(s.max_force, norm);
    s.saturated += f.saturated() ? 1 : 0;
    s.last = Eigen::Vector3d(f.force().x(), f.force().y(), f.force().z());
    s.last_flags = f.flags();
    if ((f.flags() & msg::kFlagInputLost) == 0)
      ++s.used_commands;
    else
      ++s.input_lost;
  }
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
  // The energy the environment (the haptic node's force) gave the device, the integral of F . v dt over the run
  // (the force held over each step, the step's velocity); <= 0 throughout for a passive environment.
  double energy = 0, energy_max = 0;
  for (const auto& p : s) {
    energy += p.f_axis * p.v * dt;
    energy_max = std::max(energy_max, energy);
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
  j["environment_energy_j"] = energy;
  j["environment_energy_max_j"] = energy_max;
  return j;
}

// The top-level physical summary of several devices: the worst of each judged quantity (every device settled, the
// latest settling, the largest left-over motion and force error); each device's own summary is under "instruments".
nlohmann::json physical_worst(const std::vector<nlohmann::json>& each) {
  nlohmann::json j;
  j["mode"] = "physical";
  for (const char* k : {"steps", "sim_seconds", "window_s", "settle_band_m"}) j[k] = each.front()[k];
  bool settled = true;
  for (const auto& d : each) settled = settled && d["settled"].get<bool>();
  j["settled"] = settled;
  for (const char* k :
       {"settling_time_s", "last_band_exit_s", "overshoot_m", "position_p2p_window_m", "force_p2p_window_n",
        "velocity_sign_changes_window", "force_final_error", "environment_energy_j", "environment_energy_max_j"}) {
    nlohmann::json worst = each.front()[k];
    for (const auto& d : each) worst = d[k] > worst ? d[k] : worst;
    j[k] = worst;
  }
  for (const char* k : {"band_exits_after_settling", "feedback_input_lost_steps", "end_stop_steps"}) {
    std::int64_t sum = 0;
    for (const auto& d : each) sum += d[k].get<std::int64_t>();
    j[k] = sum;
  }
  return j;
}

// Scripted motion: a slow oscillation of the insertion about `depth`, for trying a device by hand.
Pose5 scripted(double t, double depth) {
  Pose5 p;
  p.insertion = depth + 0.02 * std::sin(2 * M_PI * 0.5 * t);
  p.jaw = 0.4;
  return p;
}

// One value per instrument from an option that takes "V" (every instrument) or "V1,V2,..." (one per instrument, in
// the scene's order).
std::vector<double> per_instrument(const std::string& option, const std::string& value,
                                   const std::vector<std::string>& names) {
  const auto fields = core::text::split(value, ',');
  if (fields.size() != 1 && fields.size() != names.size())
    throw_error(option, " '", value, "': ", fields.size(), " values for the scene's ", names.size(), " instrument",
                names.size() == 1 ? "" : "s", " (", join(names),
                "): give one value for every instrument, or one per instrument in that order");
  std::vector<double> v;
  for (const auto f : fields) {
    double x = 0;
    if (core::text::parse_double(f, x) != text::Number::kOk)
      throw_error(option, " '", value, "': ", core::text::quote(f), " is not a finite number");
    v.push_back(x);
  }
  if (v.size() == 1) v.assign(names.size(), v.front());
  return v;
}

// --silence NAME[:FROM[:TO]]: no ToolCommand for that instrument while FROM <= t < TO (s; default the whole run).
struct Silence {
  int instrument = 0;
  double from = 0, to = std::numeric_limits<double>::infinity();
  bool whole_run() const { return from <= 0 && std::isinf(to); }
};

Silence parse_silence(const std::string& arg, const std::vector<std::string>& names) {
  const auto fields = core::text::split(arg, ':');
  const auto fail = [&](const std::string& what) {
    throw_error("--silence '", arg, "': ", what, " (NAME, NAME:FROM or NAME:FROM:TO, seconds from the start; the "
                "scene's instruments: ", join(names), ")");
  };
  if (fields.size() > 3) fail("too many ':'");
  Silence s;
  const auto it = std::find(names.begin(), names.end(), std::string(core::text::trim(fields[0])));
  if (it == names.end()) fail(core::text::quote(fields[0]) + " is not an instrument of the scene");
  s.instrument = static_cast<int>(it - names.begin());
  if (fields.size() > 1 && (core::text::parse_double(fields[1], s.from) != text::Number::kOk || s.from < 0))
    fail("FROM " + core::text::quote(fields[1]) + " is not a time >= 0");
  if (fields.size() > 2 && (core::text::parse_double(fields[2], s.to) != text::Number::kOk || !(s.to > s.from)))
    fail("TO " + core::text::quote(fields[2]) + " is not a time after FROM");
  return s;
}

bool silenced(const std::vector<Silence>& spans, int instrument, double t) {
  for (const auto& s : spans)
    if (s.instrument == instrument && t >= s.from && t < s.to) return true;
  return false;
}

// For each of the scene's instruments, its column group in the trajectory (-1: none, allowed only when that
// instrument is silenced for the whole run; never with --physical, `physical`). A single-instrument file named "tool"
// (every v1 file) drives the one instrument of a one-tool scene whatever its name; otherwise the file's names must be
// the scene's tool names.
std::vector<int> match_instruments(const MultiTrajectory& traj, const std::string& file, const Scene& scene,
                                   const std::vector<std::string>& names, const std::vector<Silence>& silences,
                                   bool physical) {
  std::vector<int> source(names.size(), -1);
  if (traj.instruments() == 1 && traj.names().front() == "tool" && names.size() == 1) {
    source[0] = 0;
    return source;
  }
  const auto fail = [&](const std::string& what, const std::string& fix) {
    throw_error(file, ": its instruments (", join(traj.names()), ") do not match the tools of scene '", scene.name,
                "' (", scene.file, ": ", join(names), "): ", what, ". Fix: ", fix);
  };
  if (traj.instruments() == 1 && traj.names().front() == "tool")
    fail("a single-instrument (v1) trajectory cannot say which of " + std::to_string(names.size()) +
             " instruments it drives",
         "play it with a one-tool scene (--scene), or write a v2 trajectory with one column group per tool (" +
             names.front() + ".pitch," + names.front() + ".yaw,...)");
  for (const auto& n : traj.names())
    if (std::find(names.begin(), names.end(), n) == names.end())
      fail("'" + n + "' is not a tool of the scene",
           "give the scene the trajectory was recorded for (--scene), or rename the column group '" + n +
               ".*' to one of the scene's tool names");
  for (std::size_t i = 0; i < names.size(); ++i) {
    source[i] = traj.find(names[i]);
    if (source[i] >= 0) continue;
    bool whole = false;
    for (const auto& s : silences) whole = whole || (s.instrument == static_cast<int>(i) && s.whole_run());
    if (!whole)
      fail("the scene's tool '" + names[i] + "' has no columns in the file",
           "add the column group " + names[i] + ".pitch,...," + names[i] +
               ".jaw or give the scene the trajectory was recorded for (--scene)" +
               (physical ? std::string(" (--physical drives every instrument)")
                         : ", or leave the instrument undriven on purpose with --silence " + names[i]));
  }
  return source;
}

// The first pose of trajectory column group `i` whose input is present.
Pose5 first_valid_pose(const MultiTrajectory& traj, int i, const std::string& file, const std::string& name) {
  for (std::size_t k = 0; k < traj.size(); ++k)
    if (traj.valid(k, i)) return traj.pose(k, i);
  throw_error(file, ": instrument '", name, "' has no sample with input present: --physical holds its first pose");
}

// One instrument: who it is, where its poses come from, and (--physical) its device.
struct Instrument {
  std::string name;
  int source = -1;  // column group in the trajectory, -1: none (scripted, or silenced for the whole run)
  std::uint64_t sent = 0, trajectory_lost = 0, silenced = 0;  // ticks with a command sent, lost in the file, silenced
  PhysicalDevice dev;
  Pose5 hold;
  Eigen::Vector3d axis = Eigen::Vector3d::Zero();
  double x = 0, v = 0;  // m, m/s along the shaft
  double travel = 0;    // m, the device's end stop: insertion stays in [0, travel] (the tool's shaft length)
  std::uint64_t end_stop_steps = 0;
  std::vector<PhysicalSample> samples;
  nlohmann::json summary;  // physical_summary
};

void write_physical_csv(const std::string& path, const std::vector<Instrument>& inst) {
  std::FILE* out = std::fopen(path.c_str(), "w");
  if (out == nullptr) throw_error(path, ": cannot create the --out file");
  // One instrument: today's columns; several: the same columns per instrument, prefixed with its name (as in a v2
  // trajectory).
  const bool prefix = inst.size() > 1;
  std::fprintf(out, "t");
  for (const auto& d : inst) {
    const std::string p = prefix ? d.name + "." : "";
    for (const char* c : {"insertion_m", "velocity_m_s", "force_axis_n", "fx", "fy", "fz", "flags"})
      std::fprintf(out, ",%s%s", p.c_str(), c);
  }
  std::fprintf(out, "\n");
  for (std::size_t k = 0; k < inst.front().samples.size(); ++k) {
    std::fprintf(out, "%.4f", inst.front().samples[k].t);
    for (const auto& d : inst) {
      const PhysicalSample& s = d.samples[k];
      std::fprintf(out, ",%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%u", s.x, s.v, s.f_axis, s.f.x(), s.f.y(), s.f.z(), s.flags);
    }
    std::fprintf(out, "\n");
  }
  if (std::fclose(out) != 0) throw_error(path, ": write error on the --out file");
}

nlohmann::json feedback_json(const FeedbackStats& s) {
  nlohmann::json j;
  j["received"] = s.received;
  j["force_max_n"] = s.max_force;
  j["saturated"] = s.saturated;
  j["nonfinite"] = s.nonfinite;
  j["input_lost_flagged"] = s.input_lost;
  j["last_force_n"] = {s.last.x(), s.last.y(), s.last.z()};
  j["last_flags"] = s.last_flags;
  return j;
}

}  // namespace

int main(int argc, char** argv) {
  std::string trajectory, stats, profiles, participant, out_csv, scene_name = "liver";
  double rate = 1000, duration = -1, depth = 0.16;
  int domain = -1, rt_priority = 0, dds_rt_priority = 20;
  double wait_for_haptic = 0;
  bool physical = false;
  PhysicalDevice dev;
  std::string mass_list = "0.1", damping_list = "0.5", hand_list = "2", insertion_list = "0.155";
  std::string pitch_list = "0", yaw_list = "0", roll_list = "0", jaw_list = "0.5";
  std::vector<std::string> silence_args;
  CLI::App cli{
      "surgsim device simulator: stands in for the haptic device of every instrument of a scene. Publishes one "
      "ToolCommand (5-DOF pose, keyed by instrument) per instrument per tick like a device driver, from a trajectory "
      "file or a scripted motion, and reads the ForceFeedback the haptic node sends back, per instrument. --physical "
      "simulates one 1-D device per instrument along its shaft (mass, damping, a constant hand force) driven by its "
      "instrument's force, closing each loop over DDS.\n\nPer-instrument values (--mass, --damping, --hand-force, "
      "--insertion, --pitch, --yaw, --roll, --jaw): one number for every instrument, or a comma list with one per "
      "instrument in the order of the scene's tools list (e.g. --hand-force 1,2.5)."};
  cli.add_option("--scene", scene_name,
                 "Scene (shipped name or YAML file) whose tools are the instruments driven: their names, order "
                 "(instrument index) and, with --physical, shaft axes. Use the haptic node's scene")
      ->capture_default_str();
  cli.add_option("--trajectory", trajectory,
                 "Trajectory file to play (default: the scripted poke on every instrument). A v1 file drives the tool "
                 "of a one-tool scene; a v2 file's column groups drive the scene's tools of the same names (an "
                 "instrument whose input the file says was lost gets no command). With --physical each instrument's "
                 "first pose is held");
  cli.add_option("--silence", silence_args,
                 "NAME[:FROM[:TO]]: publish nothing for instrument NAME from FROM to TO s after the start (default "
                 "the whole run; repeatable), as an unplugged device: the haptic node times that instrument out. "
                 "Not with --physical")
      ->allow_extra_args(false)
      ->take_all();
  cli.add_option("--rate", rate, "Publication rate, Hz (--physical: also the integration rate)")->capture_default_str();
  cli.add_option("--duration", duration,
                 "Seconds to run (default: trajectory length + 0.5 s, --physical 5 s, else until SIGINT)");
  cli.add_option("--depth", depth, "Mean insertion of the scripted motion, m")->capture_default_str();
  cli.add_option("--wait-for-haptic", wait_for_haptic, "Wait up to S seconds for a haptic node to subscribe");
  cli.add_option("--stats", stats,
                 "JSON summary on exit: totals over every instrument and an \"instruments\" list with each one's "
                 "commands and ForceFeedback statistics (and its device's summary with --physical)");
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
               "Simulated devices, one per instrument: m x'' = F_hand - b x' + F_feedback . axis along its shaft, "
               "at --rate, between end stops at insertion 0 and the tool's shaft length");
  cli.add_option("--mass", mass_list, "--physical: moving mass, kg (per instrument)")->capture_default_str();
  cli.add_option("--damping", damping_list, "--physical: the device's own viscous damping, N s/m (per instrument)")
      ->capture_default_str();
  cli.add_option("--hand-force", hand_list,
                 "--physical: constant hand force along the shaft (into the body), N (per instrument)")
      ->capture_default_str();
  cli.add_option("--insertion", insertion_list,
                 "--physical: starting insertion, m (per instrument; default: the trajectory's first pose, else 0.155, "
                 "the tip 5 mm above the shipped liver)");
  cli.add_option("--pitch", pitch_list, "--physical: held pitch, rad (per instrument; given, it overrides the trajectory's)")
      ->capture_default_str();
  cli.add_option("--yaw", yaw_list, "--physical: held yaw, rad (per instrument; given, it overrides the trajectory's)")
      ->capture_default_str();
  cli.add_option("--roll", roll_list, "--physical: held roll, rad (per instrument; given, it overrides the trajectory's)")
      ->capture_default_str();
  cli.add_option("--jaw", jaw_list,
                 "--physical: held jaw opening, rad (per instrument; given, it overrides the trajectory's)")
      ->capture_default_str();
  cli.add_option("--window", dev.window, "--physical: final window for oscillation and resting force, s")
      ->capture_default_str();
  cli.add_option("--settle-band", dev.band, "--physical: settling band of the position, m")->capture_default_str();
  cli.add_option("--out", out_csv,
                 "--physical: per-step CSV (t, then insertion, velocity, force along the shaft, force, flags; with "
                 "several instruments each column prefixed with the instrument's name)");
  CLI11_PARSE(cli, argc, argv);

  try {
    if (!(rate >= 1 && rate <= 20000)) throw_error("--rate ", rate, " Hz is out of range [1, 20000]");
    const Scene scene = load_scene(resolve_scene_path(scene_name));
    std::vector<std::string> names;
    for (const auto& t : scene.tools) names.push_back(t.name);
    std::vector<Instrument> inst(names.size());
    for (std::size_t i = 0; i < inst.size(); ++i) inst[i].name = names[i];

    std::vector<Silence> silences;
    for (const auto& a : silence_args) silences.push_back(parse_silence(a, names));
    if (physical && !silences.empty())
      throw_error("--silence is for trajectory and scripted playback: with --physical every device closes its loop "
                  "(stop the device process to lose its input)");

    MultiTrajectory traj;
    if (!trajectory.empty()) {
      traj = MultiTrajectory::load(trajectory);
      const std::vector<int> source = match_instruments(traj, trajectory, scene, names, silences, physical);
      for (std::size_t i = 0; i < inst.size(); ++i) inst[i].source = source[i];
    }
    if (duration < 0 && !trajectory.empty() && !physical) duration = traj.duration() + 0.5;
    if (duration < 0 && physical) duration = 5.0;
    if (physical) {
      const auto mass = per_instrument("--mass", mass_list, names);
      const auto damping = per_instrument("--damping", damping_list, names);
      const auto hand = per_instrument("--hand-force", hand_list, names);
      const auto insertion = per_instrument("--insertion", insertion_list, names);
      const auto pitch = per_instrument("--pitch", pitch_list, names);
      const auto yaw = per_instrument("--yaw", yaw_list, names);
      const auto roll = per_instrument("--roll", roll_list, names);
      const auto jaw = per_instrument("--jaw", jaw_list, names);
      if (!(dev.window > 0 && dev.window < duration)) throw_error("--window ", dev.window, " s: must be in (0, --duration)");
      for (std::size_t i = 0; i < inst.size(); ++i) {
        Instrument& d = inst[i];
        const std::string who = names.size() > 1 ? " (instrument " + d.name + ")" : "";
        d.dev = dev;
        d.dev.mass = mass[i];
        d.dev.damping = damping[i];
        d.dev.hand_force = hand[i];
        if (!(d.dev.mass > 0)) throw_error("--mass ", d.dev.mass, " kg", who, ": must be > 0");
        if (!(d.dev.damping >= 0)) throw_error("--damping ", d.dev.damping, " N s/m", who, ": must be >= 0");
        // The held pose: the trajectory's first pose with input present, else the flags; a flag given explicitly
        // overrides the trajectory's value.
        const bool from_file = d.source >= 0;
        if (from_file) d.hold = first_valid_pose(traj, d.source, trajectory, d.name);
        if (!from_file || cli.count("--insertion") > 0) d.hold.insertion = insertion[i];
        if (!from_file || cli.count("--pitch") > 0) d.hold.pitch = pitch[i];
        if (!from_file || cli.count("--yaw") > 0) d.hold.yaw = yaw[i];
        if (!from_file || cli.count("--roll") > 0) d.hold.roll = roll[i];
        if (!from_file || cli.count("--jaw") > 0) d.hold.jaw = jaw[i];
        d.axis = tool_geometry(scene.tools[i], d.hold).direction;
        d.travel = scene.tools[i].shaft_length;
        if (!(d.hold.insertion >= 0 && d.hold.insertion <= d.travel))
          throw_error(from_file && cli.count("--insertion") == 0 ? trajectory + ": the first insertion " : "--insertion ",
                      d.hold.insertion, " m", who, ": outside the device's travel [0, ", d.travel,
                      "] m (the tool's shaft_length)");
      }
    }

    sdds::DdsOptions o;
    o.domain = domain >= 0 ? domain : sdds::default_domain();
    o.profiles_file = profiles.empty() ? config_dir() + "/dds/profiles.xml" : profiles;
    o.participant_profile = participant;
    o.name = "surgsim_device_sim";
    // The DDS threads start at SCHED_FIFO below the loop (as in the haptic node), never at or above it.
    std::optional<ScopedFifo> dds_priority(std::in_place,
                                           rt_priority > 1 ? std::clamp(dds_rt_priority, 0, rt_priority - 1) : 0);
    // The listener outlives the participant: its reader may call it until the participant is gone.
    ForceListener forces(static_cast<int>(inst.size()));
    sdds::Participant p(o);
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
    {
      std::ostringstream os;
      for (std::size_t i = 0; i < inst.size(); ++i) {
        os << (i ? ", " : "") << i << " " << inst[i].name;
        if (inst[i].source >= 0 && traj.names()[inst[i].source] != inst[i].name)
          os << " (trajectory '" << traj.names()[inst[i].source] << "')";
        if (inst[i].source < 0 && !trajectory.empty()) os << " (not in the trajectory: silenced)";
      }
      std::cerr << "device_sim: scene '" << scene.name << "', " << inst.size() << " instrument"
                << (inst.size() == 1 ? "" : "s") << ": " << os.str() << "\n";
    }

    nlohmann::json summary;
    msg::ToolCommand cmd;
    std::uint64_t commands = 0;
    const auto send = [&](std::size_t i, std::uint64_t seq, const Pose5& pose) {
      cmd.instrument(static_cast<std::uint32_t>(i));
      cmd.seq(seq);
      cmd.stamp_ns(monotonic_ns());
      cmd.pose().pitch(pose.pitch);
      cmd.pose().yaw(pose.yaw);
      cmd.pose().insertion(pose.insertion);
      cmd.pose().roll(pose.roll);
      cmd.pose().jaw(pose.jaw);
      writer->write(&cmd);
      ++inst[i].sent;
      ++commands;
    };
    const RealtimeStatus rt = enter_realtime(rt_priority, false);
    if (rt_priority > 0) std::cerr << "device_sim: " << rt.note << "\n";
    summary["realtime"] = rt.note;
    PeriodicTimer timer(static_cast<std::int64_t>(1e9 / rate));
    timer.start();
    std::uint64_t k = 0;  // ticks; a command's seq is its tick (the same for every instrument in a tick)
    if (!physical) {
      const std::uint64_t t0 = monotonic_ns();
      for (;; ++k) {
        timer.wait();
        const double t = static_cast<double>(monotonic_ns() - t0) * 1e-9;
        if (g_stop || (duration >= 0 && t > duration)) break;
        for (std::size_t i = 0; i < inst.size(); ++i) {
          if (silenced(silences, static_cast<int>(i), t)) {
            ++inst[i].silenced;
            continue;
          }
          Pose5 pose = scripted(t, depth);
          if (!trajectory.empty() && !traj.at(inst[i].source, t, pose)) {
            ++inst[i].trajectory_lost;  // the file says this instrument's input was lost here: send nothing
            continue;
          }
          send(i, k, pose);
        }
      }
    } else {
      // Hold the start poses until the haptic node answers every instrument with a force computed from our commands
      // (not flagged input-lost), so the run starts with every loop closed; then t = 0.
      const double dt = 1.0 / rate;
      Eigen::Vector3d f;
      std::uint32_t flags = 0;
      std::uint64_t used = 0;
      const std::uint64_t until = monotonic_ns() + static_cast<std::uint64_t>(std::max(wait_for_haptic, 1.0) * 1e9);
      std::vector<std::string> waiting = names;
      while (!g_stop && monotonic_ns() < until && !waiting.empty()) {
        timer.wait();
        waiting.clear();
        for (std::size_t i = 0; i < inst.size(); ++i) {
          send(i, k, inst[i].hold);
          forces.latest(i, f, flags, used);
          if (used < 10) waiting.push_back(inst[i].name);
        }
        ++k;
      }
      if (!waiting.empty())
        throw_error("no force feedback computed from our commands for ", join(waiting),
                    " (is a haptic node running with --input device on scene '", scene.name,
                    "'? Its instruments must be this scene's)");
      for (auto& d : inst) {
        std::cerr << "device_sim: physical device" << (inst.size() > 1 ? " " + d.name : "") << ", m " << d.dev.mass
                  << " kg, b " << d.dev.damping << " N s/m, hand " << d.dev.hand_force << " N along ["
                  << d.axis.transpose() << "], from insertion " << d.hold.insertion << " m, " << duration << " s at "
                  << rate << " Hz\n";
        d.x = d.hold.insertion;
        d.v = 0;
      }
      const auto steps = static_cast<std::size_t>(std::llround(duration * rate));
      for (auto& d : inst) d.samples.reserve(steps);
      for (std::size_t s = 0; s < steps && !g_stop; ++s, ++k) {
        timer.wait();
        for (std::size_t i = 0; i < inst.size(); ++i) {
          Instrument& d = inst[i];
          forces.latest(i, f, flags, used);
          const double f_axis = f.dot(d.axis);
          const double a = (d.dev.hand_force - d.dev.damping * d.v + f_axis) / d.dev.mass;
          d.v += a * dt;  // semi-implicit Euler
          d.x += d.v * dt;
          if (d.x < 0 || d.x > d.travel) {  // the end stop: a tool past the organ (or pulled out) stops there
            d.x = std::clamp(d.x, 0.0, d.travel);
            d.v = 0;
            ++d.end_stop_steps;
          }
          Pose5 pose = d.hold;
          pose.insertion = d.x;
          send(i, k, pose);
          d.samples.push_back({static_cast<double>(s + 1) * dt, d.x, d.v, f_axis, f, flags});
        }
      }
      if (inst.front().samples.empty()) throw_error("stopped before the first physical step");
      std::vector<nlohmann::json> each;
      for (auto& d : inst) {
        d.summary = physical_summary(d.dev, d.samples, dt);
        d.summary["end_stop_steps"] = d.end_stop_steps;
        each.push_back(d.summary);
      }
      // One device: its summary at the top level, as before several instruments; several: the worst of each.
      summary.update(inst.size() == 1 ? each.front() : physical_worst(each));
      summary["deadline_misses"] = timer.misses();
      if (!out_csv.empty()) write_physical_csv(out_csv, inst);
      for (const auto& d : inst) {
        const nlohmann::json& j = d.summary;
        std::cerr << "device_sim: " << (inst.size() > 1 ? d.name + ": " : "") << "settling time "
                  << j["settling_time_s"].get<double>() << " s (" << (j["settled"].get<bool>() ? "settled" : "NOT settled")
                  << ", " << j["band_exits_after_settling"] << " excursions later, last back in the band at "
                  << j["last_band_exit_s"].get<double>() << " s), over the last " << d.dev.window
                  << " s: position p-p " << j["position_p2p_window_m"].get<double>() * 1e3 << " mm, force p-p "
                  << j["force_p2p_window_n"].get<double>() << " N, " << j["velocity_sign_changes_window"]
                  << " velocity sign changes; resting force " << j["force_final_n"].get<double>() << " N against "
                  << d.dev.hand_force << " N from the hand (" << j["force_final_error"].get<double>() * 100
                  << " % off), overshoot " << j["overshoot_m"].get<double>() * 1e3 << " mm, peak force "
                  << j["force_peak_n"].get<double>() << " N"
                  << (d.end_stop_steps > 0 ? ", " + std::to_string(d.end_stop_steps) + " steps at an end stop" : "")
                  << "\n";
      }
    }
    std::lock_guard<std::mutex> lock(forces.mutex);
    nlohmann::json per = nlohmann::json::array();
    for (std::size_t i = 0; i < inst.size(); ++i) {
      const Instrument& d = inst[i];
      const FeedbackStats& s = forces.per[i];
      if (inst.size() > 1)
        std::cerr << "device_sim: " << d.name << " (instrument " << i << "): " << d.sent << " commands sent ("
                  << d.silenced << " ticks silenced, " << d.trajectory_lost << " lost in the trajectory), "
                  << s.received << " force samples received (" << s.input_lost << " flagged input-lost), max |F| "
                  << s.max_force << " N, " << s.saturated << " saturated, " << s.nonfinite << " non-finite, last F ["
                  << s.last.transpose() << "] N\n";
      nlohmann::json j;
      j["name"] = d.name;
      j["instrument"] = i;
      j["commands_sent"] = d.sent;
      j["silenced_ticks"] = d.silenced;
      j["trajectory_lost_ticks"] = d.trajectory_lost;
      j.update(feedback_json(s));
      if (physical) j.update(d.summary);
      per.push_back(j);
    }
    const FeedbackStats& all = forces.total;
    std::cerr << "device_sim: " << commands << " commands sent, " << all.received << " force samples received, max |F| "
              << all.max_force << " N, " << all.saturated << " saturated, " << all.nonfinite << " non-finite";
    if (forces.unknown_instrument > 0)
      std::cerr << ", " << forces.unknown_instrument << " for an instrument beyond the scene's " << inst.size()
                << " (is the haptic node on another scene?)";
    std::cerr << "\n";
    if (!stats.empty()) {
      nlohmann::json j = summary;
      j["scene"] = scene.name;
      j["ticks"] = k;
      j["commands_sent"] = commands;
      j["forces_received"] = all.received;
      j["force_max_n"] = all.max_force;
      j["saturated"] = all.saturated;
      j["nonfinite"] = all.nonfinite;
      j["forces_unknown_instrument"] = forces.unknown_instrument;
      j["instruments"] = per;
      write_json_file(stats, j);
    }
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "device_sim: " << e.what() << "\n";
    return 1;
  }
}
