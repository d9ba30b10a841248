// The haptic node as a real process: replays are bit-identical at --speed max, the live device path (device
// simulator -> haptic node over DDS) gives the same contacts as the replay of the same motion, and --record writes a
// trajectory that replays to the same log.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "node_test.h"
#include "process.h"

namespace surgsim {
namespace {

namespace fs = std::filesystem;
using testing::Process;

class HapticProcess : public testing::NodeTest {
 protected:
  void SetUp() override { prepare("haptic", 3); }
  std::string traj(const std::string& name) const { return std::string(SURGSIM_TEST_CONFIG_DIR) + "/trajectories/" + name; }
  int run_haptic(const std::vector<std::string>& args, const std::string& log_name) {
    Process p(bin("haptic_node"), args, env_, path(log_name));
    return p.wait(300);
  }
};

TEST_F(HapticProcess, ReplayAtMaxSpeedIsBitIdentical) {
  for (const char* run : {"a", "b"}) {
    ASSERT_EQ(run_haptic({"--scene", "liver", "--replay", traj("liver_press_slide.csv"), "--speed", "max",
                          "--rt-priority", "0", "--log", path(std::string("log_") + run + ".csv")},
                         std::string("out_") + run + ".txt"),
              0)
        << testing::read_file(path(std::string("out_") + run + ".txt"));
  }
  const std::string a = testing::read_file(path("log_a.csv"));
  const std::string b = testing::read_file(path("log_b.csv"));
  ASSERT_GT(a.size(), 1000u);
  EXPECT_TRUE(a == b) << "the two --speed max replays differ";
  // The replay did touch the organ (a log of zeros would also be identical).
  std::istringstream in(a);
  std::string line;
  int touching = 0;
  std::getline(in, line);
  while (std::getline(in, line)) touching += line.back() != '0';
  EXPECT_GT(touching, 100);
}

// A corotational liver replayed at --speed max twice gives the same log: its rotations are refreshed on simulated
// time (on its 200 Hz thread they depended on how many ticks ran between two wall-clock refreshes, and two runs
// differed from tick 370 on).
TEST_F(HapticProcess, CorotationalReplayAtMaxSpeedIsBitIdentical) {
  const std::string config = SURGSIM_TEST_CONFIG_DIR;
  std::string scene = testing::read_file(config + "/liver.yaml");
  for (const std::string folder : {"curves/", "trajectories/"}) {
    for (std::size_t at = scene.find(": " + folder); at != std::string::npos; at = scene.find(": " + folder, at + 2))
      scene.insert(at + 2, config + "/");
  }
  scene += "liver:\n  deformation: corotational\n";
  {
    std::ofstream out(path("liver_corotational.yaml"));
    out << scene;
  }
  for (const char* run : {"a", "b"}) {
    ASSERT_EQ(run_haptic({"--scene", path("liver_corotational.yaml"), "--replay", traj("liver_press_slide.csv"),
                          "--speed", "max", "--rt-priority", "0", "--log", path(std::string("corot_") + run + ".csv")},
                         std::string("corot_out_") + run + ".txt"),
              0)
        << testing::read_file(path(std::string("corot_out_") + run + ".txt"));
  }
  const std::string a = testing::read_file(path("corot_a.csv"));
  ASSERT_GT(a.size(), 1000u);
  EXPECT_TRUE(a == testing::read_file(path("corot_b.csv"))) << "the two corotational --speed max replays differ";
  EXPECT_NE(testing::read_file(path("corot_out_a.txt")).find("corotational"), std::string::npos)
      << testing::read_file(path("corot_out_a.txt"));
}

TEST_F(HapticProcess, RecordThenReplayGivesTheSameLog) {
  ASSERT_EQ(run_haptic({"--scene", "liver", "--replay", traj("liver_poke.csv"), "--speed", "max", "--rt-priority", "0",
                        "--record", path("recorded.csv"), "--log", path("log_1.csv")},
                       "out_1.txt"),
            0);
  ASSERT_EQ(run_haptic({"--scene", "liver", "--replay", path("recorded.csv"), "--speed", "max", "--rt-priority", "0",
                        "--log", path("log_2.csv")},
                       "out_2.txt"),
            0)
      << testing::read_file(path("out_2.txt"));
  // The recording has one sample per tick, so the replay of it logs the same ticks (it then runs 0.5 s longer, past
  // its own last sample): compare every tick of the first run, line by line.
  std::istringstream a(testing::read_file(path("log_1.csv")));
  std::istringstream b(testing::read_file(path("log_2.csv")));
  std::string la, lb;
  int lines = 0;
  while (std::getline(a, la)) {
    ASSERT_TRUE(std::getline(b, lb)) << "the replay of the recording is shorter, at line " << lines;
    ASSERT_EQ(la, lb) << "first difference at line " << lines;
    ++lines;
  }
  EXPECT_GT(lines, 1000);
}

// The shipped two-instrument liver (a grasper holding the free lobe, a probe pressing beside it) replays
// bit-identically at --speed max, both instruments touch, the stats list each instrument, and --record writes a v2
// trajectory (one column group per instrument) whose replay logs the same ticks.
TEST_F(HapticProcess, TwoInstrumentReplayIsBitIdenticalAndItsRecordingReplays) {
  for (const char* run : {"a", "b"}) {
    std::vector<std::string> args = {"--scene", "liver_two_tools", "--speed", "max", "--rt-priority", "0",
                                     "--log", path(std::string("two_") + run + ".csv"), "--stats",
                                     path(std::string("two_") + run + ".json")};
    if (std::string(run) == "a") {
      args.push_back("--record");
      args.push_back(path("two_recorded.csv"));
    }
    ASSERT_EQ(run_haptic(args, std::string("two_out_") + run + ".txt"), 0)
        << testing::read_file(path(std::string("two_out_") + run + ".txt"));
  }
  const std::string a = testing::read_file(path("two_a.csv"));
  EXPECT_TRUE(a == testing::read_file(path("two_b.csv"))) << "the two --speed max replays differ";
  EXPECT_EQ(a.substr(0, a.find('\n')),
            "tick,t,fx,fy,fz,contacts,grasper.fx,grasper.fy,grasper.fz,grasper.contacts,probe.fx,probe.fy,probe.fz,"
            "probe.contacts");
  const auto stats = nlohmann::json::parse(testing::read_file(path("two_a.json")));
  ASSERT_EQ(stats["tools"].size(), 2u);
  EXPECT_EQ(stats["instrument_count"], 2);
  for (const auto& tool : stats["tools"]) {
    EXPECT_GT(tool["contacts_max"].get<int>(), 0) << tool.dump();
    EXPECT_GT(tool["force_max_n"].get<double>(), 0.05) << tool.dump();
    EXPECT_EQ(tool["input_lost_ticks"].get<long>(), 0) << tool.dump();
  }
  EXPECT_EQ(stats["tools"][0]["name"], "grasper");
  EXPECT_EQ(stats["tools"][1]["name"], "probe");
  const std::string recorded = testing::read_file(path("two_recorded.csv"));
  ASSERT_EQ(recorded.substr(0, recorded.find('\n')), "# surgsim-trajectory v2");
  ASSERT_EQ(run_haptic({"--scene", "liver_two_tools", "--replay", path("two_recorded.csv"), "--speed", "max",
                        "--rt-priority", "0", "--log", path("two_c.csv")},
                       "two_out_c.txt"),
            0)
      << testing::read_file(path("two_out_c.txt"));
  std::istringstream la(a), lc(testing::read_file(path("two_c.csv")));
  std::string x, y;
  int lines = 0;
  while (std::getline(la, x)) {
    ASSERT_TRUE(std::getline(lc, y)) << "the replay of the recording is shorter, at line " << lines;
    ASSERT_EQ(x, y) << "first difference at line " << lines;
    ++lines;
  }
  EXPECT_GT(lines, 1000);
}

TEST_F(HapticProcess, LiveDevicePathMatchesReplay) {
  // Replay of the poke.
  ASSERT_EQ(run_haptic({"--scene", "liver", "--replay", traj("liver_poke.csv"), "--speed", "max", "--rt-priority", "0",
                        "--stats", path("replay.json")},
                       "replay.txt"),
            0);
  // The same motion from a device process, in real time over DDS.
  Process haptic(bin("haptic_node"),
                 {"--scene", "liver", "--input", "device", "--duration", "6", "--rt-priority", "0", "--stats",
                  path("live.json"), "--record", path("live_record.csv")},
                 env_, path("live.txt"));
  Process device(bin("surgsim-device-sim"),
                 {"--trajectory", traj("liver_poke.csv"), "--rate", "1000", "--wait-for-haptic", "60", "--stats",
                  path("device.json")},
                 env_, path("device.txt"));
  ASSERT_EQ(device.wait(120), 0) << testing::read_file(path("device.txt"));
  ASSERT_EQ(haptic.wait(120), 0) << testing::read_file(path("live.txt"));

  const auto replay = nlohmann::json::parse(testing::read_file(path("replay.json")));
  const auto live = nlohmann::json::parse(testing::read_file(path("live.json")));
  const auto dev = nlohmann::json::parse(testing::read_file(path("device.json")));
  EXPECT_EQ(live["input"], "device");
  EXPECT_GT(live["commands_received"].get<long>(), 1000);
  // Same contacts: same largest contact set, about the same time in contact and the same peak force.
  EXPECT_EQ(live["contacts_max"], replay["contacts_max"]);
  const double t_replay = replay["contact_ticks"].get<double>();
  const double t_live = live["contact_ticks"].get<double>();
  // A loaded machine skips ticks (each counted as a missed deadline): those cannot be in contact, so they widen the
  // tolerance (found failing under ctest -j2 next to compiles: 474 against 515 ticks in contact).
  const double skipped = live["deadline_misses"].get<double>();
  EXPECT_NEAR(t_live, t_replay, 0.05 * t_replay + skipped) << skipped << " missed deadlines";
  EXPECT_NEAR(live["force_max_n"].get<double>(), replay["force_max_n"].get<double>(),
              0.05 * replay["force_max_n"].get<double>());
  // The device got the forces back, all finite.
  EXPECT_GT(dev["forces_received"].get<long>(), 100);
  EXPECT_EQ(dev["nonfinite"].get<long>(), 0);
  EXPECT_NEAR(dev["force_max_n"].get<double>(), live["force_max_n"].get<double>(), 1e-9);
  // Before the first command and after the last, the input is lost: zero force, counted.
  EXPECT_GT(live["input_lost_ticks"].get<long>(), 0);
  // What was used was recorded.
  EXPECT_GT(testing::read_file(path("live_record.csv")).size(), 1000u);
}

}  // namespace
}  // namespace surgsim

namespace surgsim {
namespace {

// The shipped field (config/abdomen.yaml: liver, bowel, wall, floor, ribs; two instruments) replays bit-identically
// at --speed max; the stats list every organ in the scene's order, each instrument touches, and the wall held the
// probe within the 1 mm budget of the issue during its slide.
TEST_F(HapticProcess, FieldOfSeveralOrgansReplaysBitIdentically) {
  for (const char* run : {"a", "b"}) {
    const std::vector<std::string> args = {"--scene", "abdomen", "--speed", "max", "--rt-priority", "0", "--log",
                                           path(std::string("field_") + run + ".csv"), "--stats",
                                           path(std::string("field_") + run + ".json")};
    ASSERT_EQ(run_haptic(args, std::string("field_out_") + run + ".txt"), 0)
        << testing::read_file(path(std::string("field_out_") + run + ".txt"));
  }
  EXPECT_TRUE(testing::read_file(path("field_a.csv")) == testing::read_file(path("field_b.csv")))
      << "the two --speed max replays of the field differ";
  const auto stats = nlohmann::json::parse(testing::read_file(path("field_a.json")));
  EXPECT_EQ(stats["model_built"], "organs");
  ASSERT_EQ(stats["organs"].size(), 5u) << stats["organs"].dump();
  const char* names[] = {"liver", "bowel", "wall", "floor", "ribs"};
  const char* models[] = {"liver", "intestine", "rigid", "rigid", "rigid"};
  for (std::size_t k = 0; k < 5; ++k) {
    EXPECT_EQ(stats["organs"][k]["name"], names[k]);
    EXPECT_EQ(stats["organs"][k]["model"], models[k]);
  }
  for (const auto& tool : stats["tools"]) EXPECT_GT(tool["contacts_max"].get<int>(), 0) << tool.dump();
  const auto& wall = stats["organs"][2]["rigid"]["instruments"];
  EXPECT_GT(wall[0]["contact_ticks"].get<long>(), 1000) << "the probe slides on the wall for 2 s";
  EXPECT_LE(wall[0]["max_penetration_mm"].get<double>(), 1.0);
}

}  // namespace
}  // namespace surgsim
