// The haptic loop closed through a simulated device over DDS: the real haptic_node on the shipped
// liver at 1 kHz and the real surgsim-device-sim --physical (a mass along the shaft with its own damping and a
// constant hand force, integrating the ForceFeedback it receives) on a private domain. At the corners of the grid
// (mass 0.05-0.2 kg, damping 0.1-1 N s/m, hand force 0.5-3 N) the tool must come to rest, without sustained
// oscillation, pressing with the hand's force (within 10 %). With two instruments each device closes its
// loop with its own instrument's force: each rests pressing with its own hand's force.
//
// Robust to a loaded 2-core machine: the device integrates in simulated time (a late wake-up delays a step, it does
// not lengthen it), the run is 6 s against settling times of 0.1-0.8 s on the development VM, the rest is judged
// over the last second, and nothing is asserted about wall-clock speed (misses and settling time are recorded).
#include <gtest/gtest.h>

#include <algorithm>
#include <csignal>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "device_sim_scene.h"
#include "node_test.h"
#include "process.h"

namespace surgsim {
namespace {

using testing::Process;

// The shipped scene config/NAME.yaml with each (from, to) of `edits` replaced once, written to `file` with its curves
// and trajectory by absolute path (so it reads the shipped files from the test's folder and its cached tensors
// serve). Returns `file`.
std::string write_shipped(const std::string& name, const std::string& file,
                          const std::vector<std::pair<std::string, std::string>>& edits) {
  std::string text = testing::read_file(std::string(SURGSIM_TEST_CONFIG_DIR) + "/" + name + ".yaml");
  const auto replace = [&](const std::string& from, const std::string& to) {
    const std::size_t at = text.find(from);
    if (at == std::string::npos) throw std::runtime_error(name + ".yaml has no '" + from + "' any more");
    text.replace(at, from.size(), to);
  };
  const std::string config = SURGSIM_TEST_CONFIG_DIR;
  replace("displacement_curve: curves/", "displacement_curve: " + config + "/curves/");
  replace("force_curve: curves/", "force_curve: " + config + "/curves/");
  replace("trajectory: trajectories/", "trajectory: " + config + "/trajectories/");
  for (const auto& [from, to] : edits) replace(from, to);
  std::ofstream out(file);
  out << text;
  if (!out) throw std::runtime_error("cannot write " + file);
  return file;
}

// The shipped liver scene with the force stage's keys set (haptic: passivity, coupling_damping).
std::string write_liver(const std::string& file, bool passivity, double coupling_damping) {
  return write_shipped("liver", file,
                       {{"\nhaptic:\n", "\nhaptic:\n  passivity: " + std::string(passivity ? "true" : "false") +
                                            "\n  coupling_damping: " + std::to_string(coupling_damping) + "\n"}});
}

// The insertion's peak-to-peak over each whole second of a one-instrument device CSV (surgsim-device-sim --out).
std::vector<double> p2p_per_second(const std::string& csv) {
  std::istringstream in(testing::read_file(csv));
  std::string line;
  std::getline(in, line);
  if (line.rfind("t,insertion_m,", 0) != 0) throw std::runtime_error(csv + ": unexpected header " + line);
  std::vector<double> lo, hi;
  while (std::getline(in, line)) {
    const std::size_t c1 = line.find(','), c2 = line.find(',', c1 + 1);
    const double t = std::stod(line.substr(0, c1)), x = std::stod(line.substr(c1 + 1, c2 - c1 - 1));
    const auto s = static_cast<std::size_t>(t);
    if (s >= lo.size()) {
      lo.resize(s + 1, 1e300);
      hi.resize(s + 1, -1e300);
    }
    lo[s] = std::min(lo[s], x);
    hi[s] = std::max(hi[s], x);
  }
  std::vector<double> p2p;
  for (std::size_t s = 0; s < lo.size(); ++s) p2p.push_back(hi[s] >= lo[s] ? hi[s] - lo[s] : 0);
  return p2p;
}

class DevicePhysical : public testing::NodeTest {
 protected:
  void SetUp() override { prepare("device_physical", 23); }

  // One closed-loop run on `scene` with the device's own options `device_args` (mass, damping, hand force);
  // returns the device's summary (surgsim-device-sim --stats) and leaves the node's in `node`.
  nlohmann::json run(const std::string& scene, const std::vector<std::string>& device_args, const std::string& tag,
                     nlohmann::json& node) {
    Process haptic(bin("haptic_node"),
                   {"--scene", scene, "--input", "device", "--rate", "1000", "--duration", "600", "--stats",
                    path(tag + "_haptic.json")},
                   env_, path(tag + "_haptic.txt"));
    std::vector<std::string> args = {"--physical", "--scene", scene, "--duration", "6", "--window", "1",
                                     "--settle-band", "0.001", "--rate", "1000", "--rt-priority", "70",
                                     "--wait-for-haptic", "120", "--out", path(tag + "_device.csv"), "--stats",
                                     path(tag + "_device.json")};
    args.insert(args.end(), device_args.begin(), device_args.end());
    Process device(bin("surgsim-device-sim"), args, env_, path(tag + "_device.txt"));
    const int device_rc = device.wait(300);
    haptic.signal(SIGINT);
    const int haptic_rc = haptic.wait(60);
    EXPECT_EQ(device_rc, 0) << testing::read_file(path(tag + "_device.txt"));
    EXPECT_EQ(haptic_rc, 0) << testing::read_file(path(tag + "_haptic.txt"));
    if (device_rc != 0 || haptic_rc != 0) return {};
    node = json(path(tag + "_haptic.json"));
    return json(path(tag + "_device.json"));
  }

  // One device's summary `d` (the top level of a one-instrument run, or one entry of "instruments"): at rest,
  // pressing with the hand's force. `misses`: deadlines missed by either process in the run.
  // `disturbed_p2p`: the motion (m) a missed deadline may leave in the last window (below).
  static void expect_at_rest(const nlohmann::json& d, double hand, double misses, double disturbed_p2p = 5e-3) {
    // At rest: within 1 mm of its final position for the whole last second (a sustained oscillation of this loop is
    // 3-60 mm peak to peak). An overrun of either process on a loaded machine holds, then fades the force for up to
    // 10 ms while the hand keeps pushing, which nudges a light tool by 0.1-3 mm (seen under ctest -j2 on 2 cores): with
    // missed deadlines the run must still have come to rest once (settling time found) and not ring (below).
    // Came to rest for a whole window at some point (the 6 s run with its 1 s window: by 5 s at the latest).
    EXPECT_LE(d["settling_time_s"].get<double>(), 5.0) << "never came to rest for a whole window";
    if (misses == 0) {
      EXPECT_TRUE(d["settled"].get<bool>()) << "settling time " << d["settling_time_s"];
      EXPECT_LT(d["position_p2p_window_m"].get<double>(), 1e-3);
    } else {
      EXPECT_LT(d["position_p2p_window_m"].get<double>(), disturbed_p2p) << misses << " missed deadlines";
    }
    // ... and no ringing: without the force stage the light corner keeps a 12 Hz ring (about 24 velocity reversals a
    // second, 0.3-0.5 mm) after its large swings die out; an overrun's nudge reverses the velocity once or twice.
    EXPECT_LE(d["velocity_sign_changes_window"].get<int>(), 10);
    // Resting on the liver with the hand's force (within 10 %).
    EXPECT_NEAR(d["force_final_n"].get<double>(), hand, 0.1 * hand);
  }

  void expect_rest(double mass, double damping, double hand, const std::string& tag) {
    nlohmann::json node;
    const nlohmann::json d = run("liver",
                                 {"--mass", std::to_string(mass), "--damping", std::to_string(damping), "--hand-force",
                                  std::to_string(hand)},
                                 tag, node);
    ASSERT_FALSE(d.is_null());
    SCOPED_TRACE(d.dump(2));
    // The loop was closed: the node used the device's commands and the device got forces back, all finite.
    EXPECT_GT(node["commands_received"].get<double>(), 3000);
    EXPECT_GT(d["forces_received"].get<double>(), 3000);
    EXPECT_EQ(d["nonfinite"].get<int>(), 0);
    EXPECT_TRUE(node.contains("force_stage"));
    // One instrument: the summary at the top level, and the same under "instruments".
    ASSERT_EQ(d["instruments"].size(), 1u);
    EXPECT_EQ(d["instruments"][0]["force_final_n"], d["force_final_n"]);
    const double misses = d["deadline_misses"].get<double>() + node["deadline_misses"].get<double>();
    expect_at_rest(d, hand, misses);
    RecordProperty("settling_time_s", std::to_string(d["settling_time_s"].get<double>()));
    RecordProperty("overshoot_mm", std::to_string(d["overshoot_m"].get<double>() * 1e3));
    RecordProperty("force_final_n", std::to_string(d["force_final_n"].get<double>()));
    RecordProperty("device_deadline_misses", std::to_string(d["deadline_misses"].get<double>()));
    RecordProperty("haptic_deadline_misses", std::to_string(node["deadline_misses"].get<double>()));
  }
};

// Light, barely damped, pushed hard: the corner most prone to ring (the 44 mm overshoot case).
TEST_F(DevicePhysical, LightUndampedHardPushComesToRest) { expect_rest(0.05, 0.1, 3.0, "light"); }

// The negative controls of that corner. The device holds each force the node sends until the next one arrives (a
// sample-and-hold): on the liver that hands the light, barely damped tool more energy a tick than its own damping
// takes. Without the force stage (haptic: {passivity: false, coupling_damping: 0}, the organ's own force sent) the
// tool keeps bouncing on the liver, 10-15 cm peak to peak at about 4 Hz (the development VM), and the observer, which
// still runs, sees the energy handed out. On a loaded machine a late tick only adds to the motion.
TEST_F(DevicePhysical, LightCornerKeepsBouncingWithoutTheForceStage) {
  nlohmann::json node;
  const std::string scene = write_liver(path("liver_stage_off.yaml"), false, 0.0);
  const nlohmann::json d = run(scene, {"--mass", "0.05", "--damping", "0.1", "--hand-force", "3"}, "off", node);
  ASSERT_FALSE(d.is_null());
  SCOPED_TRACE(d.dump(2));
  const std::vector<double> p2p = p2p_per_second(path("off_device.csv"));
  ASSERT_GE(p2p.size(), 6u);
  SCOPED_TRACE(::testing::Message() << "peak to peak, s 1: " << p2p[1] << " m, last s: " << p2p[5] << " m");
  EXPECT_GT(p2p[1], 0.02);
  EXPECT_GT(p2p[5], 0.02) << "the bounce died out";
  EXPECT_GT(p2p[5], 0.5 * p2p[1]) << "the bounce decays";
  EXPECT_FALSE(d["settled"].get<bool>());
  const nlohmann::json& stage = node["force_stage"];
  EXPECT_FALSE(stage["passivity"].get<bool>());
  EXPECT_EQ(stage["pc_ticks"].get<int>(), 0);
  EXPECT_LT(stage["energy_min_j"].get<double>(), -0.1) << "the observer must see the energy the hold hands out";
  RecordProperty("p2p_last_s_mm", std::to_string(p2p[5] * 1e3));
  RecordProperty("observer_energy_min_j", std::to_string(stage["energy_min_j"].get<double>()));
}

// ... and with the passivity controller alone (haptic: {passivity: true, coupling_damping: 0}): it takes out what the
// observer sees handed out, and the tool comes to rest with the hand's force (the device's own 0.1 N s/m does the rest:
// the controller adds no damping beyond the deficit, so the motion decays more slowly than with the coupling damper,
// by 2-3 times a second on the development VM). The node's stats say the controller acted.
TEST_F(DevicePhysical, LightCornerComesToRestWithThePassivityControllerAlone) {
  nlohmann::json node;
  const std::string scene = write_liver(path("liver_pc_only.yaml"), true, 0.0);
  const nlohmann::json d = run(scene, {"--mass", "0.05", "--damping", "0.1", "--hand-force", "3"}, "pc", node);
  ASSERT_FALSE(d.is_null());
  SCOPED_TRACE(d.dump(2));
  const std::vector<double> p2p = p2p_per_second(path("pc_device.csv"));
  ASSERT_GE(p2p.size(), 6u);
  SCOPED_TRACE(::testing::Message() << "peak to peak, s 1: " << p2p[1] << " m, last s: " << p2p[5] << " m");
  // The motion decays to rest. A late tick's nudge on a loaded machine (0.1-3 mm, see expect_at_rest) rings down
  // slowly here, as nothing but the device's own 0.1 N s/m damps the tool between the controller's acts (a time
  // constant of 2 m / b = 1 s): with 23 missed deadlines (CI, 2 cores) the last second still moved 15 mm, 59 % of the
  // second one's; with 196, 15.7 mm; once 21 mm. No fixed bound separates that from the stage-off bounce on every
  // load, so with misses the run is judged against a stage-off run made right after it, under the same load: the
  // controller must take out at least half of the motion the stage-off loop keeps (10-15 cm on the development VM).
  const double misses = d["deadline_misses"].get<double>() + node["deadline_misses"].get<double>();
  if (misses == 0) {
    EXPECT_LT(p2p[5], 0.25 * p2p[1]) << "the motion does not die out";
    EXPECT_LT(p2p[5], 5e-3);
  } else {
    nlohmann::json off_node;
    const std::string off_scene = write_liver(path("liver_stage_off.yaml"), false, 0.0);
    const nlohmann::json off =
        run(off_scene, {"--mass", "0.05", "--damping", "0.1", "--hand-force", "3"}, "pc_off", off_node);
    ASSERT_FALSE(off.is_null());
    const std::vector<double> off_p2p = p2p_per_second(path("pc_off_device.csv"));
    ASSERT_GE(off_p2p.size(), 6u);
    const double off_misses = off["deadline_misses"].get<double>() + off_node["deadline_misses"].get<double>();
    EXPECT_LT(p2p[5], 0.5 * off_p2p[5]) << "the controller does not take the motion out: " << misses
                                        << " missed deadlines; stage off, same load: " << off_p2p[5] << " m, "
                                        << off_misses << " missed deadlines";
    RecordProperty("p2p_last_s_stage_off_mm", std::to_string(off_p2p[5] * 1e3));
  }
  // ... and the tool rests pressing with the hand's force (within 10 %).
  EXPECT_NEAR(d["force_final_n"].get<double>(), 3.0, 0.3);
  EXPECT_EQ(d["nonfinite"].get<int>(), 0);
  // The controller did it.
  const nlohmann::json& stage = node["force_stage"];
  EXPECT_TRUE(stage["passivity"].get<bool>());
  EXPECT_EQ(stage["coupling_damping_ns_per_m"].get<double>(), 0.0);
  EXPECT_GT(stage["pc_ticks"].get<int>(), 0);
  EXPECT_GT(stage["energy_dissipated_pc_j"].get<double>(), 0.0);
  RecordProperty("p2p_last_s_mm", std::to_string(p2p[5] * 1e3));
  RecordProperty("pc_ticks", std::to_string(stage["pc_ticks"].get<int>()));
  RecordProperty("pc_dissipated_j", std::to_string(stage["energy_dissipated_pc_j"].get<double>()));
}

// Heavy, damped, pushed gently: a small force on a large mass.
TEST_F(DevicePhysical, HeavyDampedGentlePushComesToRest) { expect_rest(0.2, 1.0, 0.5, "heavy"); }

// Heavy and barely damped, pushed hard: the most momentum at contact.
TEST_F(DevicePhysical, HeavyUndampedHardPushComesToRest) { expect_rest(0.2, 0.1, 3.0, "heavy_hard"); }

// Two instruments, 6 cm apart on the liver's top, one device each with its own hand force (1 N and 2.5 N)
// and damping: each closes its loop with its own instrument's ForceFeedback, so each comes to rest pressing with its
// own hand's force. Had a device read the other's force (or the one instance of a keyless topic), neither could.
TEST_F(DevicePhysical, TwoInstrumentsEachRestWithTheirOwnHandForce) {
  const std::string scene = testing::write_two_probe_liver(path("two_probes.yaml"));
  const double hand[2] = {1.0, 2.5};
  nlohmann::json node;
  const nlohmann::json d = run(scene, {"--mass", "0.1", "--damping", "0.5,1", "--hand-force", "1,2.5"}, "two", node);
  ASSERT_FALSE(d.is_null());
  SCOPED_TRACE(d.dump(2));
  ASSERT_EQ(d["instruments"].size(), 2u);
  ASSERT_EQ(node["tools"].size(), 2u);
  EXPECT_EQ(d["nonfinite"].get<int>(), 0);
  EXPECT_EQ(d["forces_unknown_instrument"].get<int>(), 0);
  const double misses = d["deadline_misses"].get<double>() + node["deadline_misses"].get<double>();
  const char* names[2] = {"left", "right"};
  for (int i = 0; i < 2; ++i) {
    const nlohmann::json& e = d["instruments"][i];
    SCOPED_TRACE(names[i]);
    EXPECT_EQ(e["name"], names[i]);
    EXPECT_EQ(node["tools"][i]["name"], names[i]);
    EXPECT_EQ(e["hand_force_n"].get<double>(), hand[i]);
    EXPECT_EQ(e["damping_ns_per_m"].get<double>(), i == 0 ? 0.5 : 1.0);
    // Each loop closed: the node used this instrument's commands and this device got this instrument's forces.
    EXPECT_GT(node["tools"][i]["commands_received"].get<double>(), 3000);
    EXPECT_GT(e["received"].get<double>(), 3000);
    EXPECT_EQ(e["feedback_input_lost_steps"].get<int>(), 0);
    expect_at_rest(e, hand[i], misses);
    RecordProperty(std::string(names[i]) + "_force_final_n", std::to_string(e["force_final_n"].get<double>()));
  }
  // The top level: the worst of the two.
  EXPECT_EQ(d["settled"].get<bool>(), d["instruments"][0]["settled"].get<bool>() && d["instruments"][1]["settled"].get<bool>());
  EXPECT_EQ(d["force_final_error"].get<double>(), std::max(d["instruments"][0]["force_final_error"].get<double>(),
                                                           d["instruments"][1]["force_final_error"].get<double>()));
  // The per-step CSV: t, then seven columns per instrument, prefixed with its name.
  const std::string csv = testing::read_file(path("two_device.csv"));
  EXPECT_EQ(csv.substr(0, csv.find('\n')),
            "t,left.insertion_m,left.velocity_m_s,left.force_axis_n,left.fx,left.fy,left.fz,left.flags,"
            "right.insertion_m,right.velocity_m_s,right.force_axis_n,right.fx,right.fy,right.fz,right.flags");
}

// The several-organs field (config/abdomen.yaml) with its probe turned from its port towards the posterior abdominal
// wall (the floor, at a point clear of the liver and the bowel, as abdomen_bench's section 3). The grasper keeps its
// port and axis.
std::string write_abdomen_wall_push(const std::string& file) {
  // towards (0.17, -0.05, -0.08) on the floor, as abdomen_bench
  return write_shipped("abdomen", file, {{"axis: [-0.04, 0.07, -0.0778]", "axis: [0.12, -0.05, -0.158]"}});
}

// A rigid organ through the real nodes: the probe pushed along its shaft into the posterior abdominal wall by the
// device simulator (the grasper held still in the cavity, no hand force). The wall has no compliance: the proxy's
// coupling is the spring. At both corners of the range most prone to trouble (light and barely damped, pushed
// hard; heavy and damped, pushed gently) the probe comes to rest on the wall pressing with the hand's force, and the
// environment (the node's force as the device felt it, held over each step) gave the device no energy.
TEST_F(DevicePhysical, ProbePushedIntoTheAbdominalWallComesToRestPassively) {
  const std::string scene = write_abdomen_wall_push(path("abdomen_wall.yaml"));
  struct Corner {
    double mass, damping, hand;
    const char* tag;
  };
  for (const Corner c : {Corner{0.05, 0.1, 3.0, "wall_light"}, Corner{0.2, 1.0, 0.5, "wall_heavy"}}) {
    SCOPED_TRACE(c.tag);
    nlohmann::json node;
    const nlohmann::json d =
        run(scene,
            {"--mass", std::to_string(c.mass), "--damping", std::to_string(c.damping), "--hand-force",
             std::to_string(c.hand) + ",0", "--insertion", "0.17,0.03"},  // the probe 3.5 cm short
            c.tag, node);
    ASSERT_FALSE(d.is_null());
    SCOPED_TRACE(d.dump(2));
    ASSERT_EQ(d["instruments"].size(), 2u);
    EXPECT_EQ(d["nonfinite"].get<int>(), 0);
    const nlohmann::json& probe = d["instruments"][0];
    EXPECT_EQ(probe["name"], "probe");
    // The probe met the wall, not a deformable organ: the wall's proxy held it.
    ASSERT_TRUE(node.contains("organs")) << node.dump(2);
    bool wall_touched = false;
    for (const auto& o : node["organs"]) {
      if (o["name"] == "floor") wall_touched = o["rigid"]["instruments"][0]["contact_ticks"].get<double>() > 1000;
    }
    EXPECT_TRUE(wall_touched) << node["organs"].dump(2);
    const double misses = d["deadline_misses"].get<double>() + node["deadline_misses"].get<double>();
    // On the wall a missed deadline nudges the light corner further than on the liver: the force faded for up to
    // 10 ms under a 3 N hand moves 0.05 kg 3 mm at 0.6 m/s, and the 2 N/mm coupling stops that 3 mm later (7 mm
    // peak to peak seen under ctest -j2 with 26 misses). Still at rest once, and no ringing.
    expect_at_rest(probe, c.hand, misses, 1e-2);
    EXPECT_LE(probe["environment_energy_j"].get<double>(), 0.0);
    RecordProperty(std::string(c.tag) + "_environment_energy_j",
                   std::to_string(probe["environment_energy_j"].get<double>()));
    RecordProperty(std::string(c.tag) + "_environment_energy_max_j",
                   std::to_string(probe["environment_energy_max_j"].get<double>()));
    for (const char* k : {"settling_time_s", "overshoot_m", "position_p2p_window_m", "force_final_n"})
      RecordProperty(std::string(c.tag) + "_" + k, std::to_string(probe[k].get<double>()));
    RecordProperty(std::string(c.tag) + "_deadline_misses", std::to_string(misses));
  }
}

}  // namespace
}  // namespace surgsim
