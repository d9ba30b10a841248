// Separate machines: scripts/run_two_hosts.sh puts the haptic node and the visual node in two network
// namespaces joined by a veth pair (UDPv4 only, the visual side with its own /dev/shm), or through surgsim-netem with
// delay, jitter and loss. Needs root: where the machine refuses a namespace, a link or a TAP device, the script says
// which and the test fails with that reason; it never passes without running.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>

#include "node_test.h"
#include "process.h"

namespace surgsim {
namespace {

namespace fs = std::filesystem;
using testing::Process;

class TwoHosts : public testing::NodeTest {
 protected:
  void SetUp() override { prepare("two_hosts", 0); }  // the script runs the nodes with its own environment
  /// Runs the script; returns its summary.json (empty on failure, with the reason recorded as a test failure).
  nlohmann::json run(const std::string& name, const std::vector<std::string>& args) {
    const std::string out = (dir_ / name).string();
    std::vector<std::string> a{std::string(SURGSIM_TEST_CONFIG_DIR) + "/../scripts/run_two_hosts.sh", "--out", out};
    a.insert(a.end(), args.begin(), args.end());
    // The haptic loop at normal priority: parallel test runs share the cores.
    const std::vector<std::string> env{"SURGSIM_BUILD_DIR=" SURGSIM_TEST_BIN_DIR "/..",
                                       "SURGSIM_CONFIG_DIR=" SURGSIM_TEST_CONFIG_DIR,
                                       "SURGSIM_CACHE_DIR=" SURGSIM_TEST_CACHE_DIR, "HAPTIC_ARGS=--rt-priority 0"};
    const std::string log = (dir_ / (name + ".log")).string();
    Process p("/bin/bash", a, env, log);
    const int rc = p.wait(120);
    EXPECT_EQ(rc, 0) << "run_two_hosts.sh " << name << " (4 = the machine refused a capability):\n"
                     << testing::read_file(log) << testing::read_file(out + "/haptic.log")
                     << testing::read_file(out + "/visual.log");
    if (rc != 0) return {};
    return json(out + "/summary.json");
  }
  /// The haptic loop ran every tick of its run (deterministic). Its rate and missed deadlines are figures
  /// (scripts/network_figures.sh), not assertions: tests do not assert wall-clock speed.
  static void expect_haptic_rate_held(const nlohmann::json& s) {
    EXPECT_GT(s["ticks"].get<double>(), 0.0) << s.dump(2);
    ::testing::Test::RecordProperty("haptic_achieved_hz", std::to_string(s["achieved_hz"].get<double>()));
  }
};

TEST_F(TwoHosts, UdpMulticastOverVeth) {
  const auto s = run("udp", {"--transport", "udp", "--duration", "2"});
  ASSERT_FALSE(s.empty());
  EXPECT_EQ(s["haptic_dds_participant"], "surgsim_udp");
  EXPECT_EQ(s["visual_dds_participant"], "surgsim_udp");
  EXPECT_TRUE(s["scene_hash_ok"].get<bool>()) << "SceneInfo crossed the link";
  const double ticks = s["ticks"].get<double>();
  EXPECT_EQ(ticks, 2.0 * s["rate_hz"].get<double>());
  EXPECT_GT(s["frames_received"].get<double>(), 0.9 * ticks) << s.dump(2);
  EXPECT_GT(s["round_trips"].get<double>(), 0.9 * ticks) << s.dump(2);
  EXPECT_GT(s["round_trip_us"]["p50"].get<double>(), 0.0);
  expect_haptic_rate_held(s);
}

TEST_F(TwoHosts, UnicastDiscoveryWithoutMulticast) {
  // Initial peers, then a Discovery Server (fastdds discovery in the haptic namespace); multicast is off on the link.
  for (const char* transport : {"peers", "ds"}) {
    const auto s = run(transport, {"--transport", transport, "--duration", "1"});
    ASSERT_FALSE(s.empty()) << transport;
    EXPECT_EQ(s["visual_dds_participant"], transport == std::string("peers") ? "surgsim_udp_peers" : "surgsim_ds_client");
    EXPECT_GT(s["frames_received"].get<double>(), 0.9 * s["ticks"].get<double>()) << transport << s.dump(2);
    EXPECT_GT(s["round_trips"].get<double>(), 0.9 * s["ticks"].get<double>()) << transport << s.dump(2);
    EXPECT_TRUE(s["scene_hash_ok"].get<bool>()) << transport;
  }
}

TEST_F(TwoHosts, ImpairedLinkKeepsTheHapticRate) {
  const auto s = run("impaired", {"--impair", "delay=5ms,jitter=2ms,loss=5%", "--seed", "7", "--duration", "3"});
  ASSERT_FALSE(s.empty());
  // The wire did impair: frames dropped both ways, the delay in the round trip (2 x (5 +- 2) ms + processing).
  const auto& n = s["netem"];
  for (const char* d : {"a_to_b", "b_to_a"}) {
    EXPECT_GT(n[d]["dropped"].get<double>(), 0.01 * n[d]["received"].get<double>()) << d;
    EXPECT_LT(n[d]["dropped"].get<double>(), 0.12 * n[d]["received"].get<double>()) << d;
  }
  EXPECT_GE(s["round_trip_us"]["p50"].get<double>(), 6000.0) << s.dump(2);
  EXPECT_LE(s["round_trip_us"]["p50"].get<double>(), 20000.0) << s.dump(2);
  // The visual node still gets most frames (about 5 % lost) and the haptic loop does not notice the network.
  const double ticks = s["ticks"].get<double>();
  EXPECT_GT(s["frames_received"].get<double>(), 0.8 * ticks) << s.dump(2);
  EXPECT_GT(s["round_trips"].get<double>(), 0.5 * ticks) << s.dump(2);
  EXPECT_TRUE(s["scene_hash_ok"].get<bool>()) << "reliable SceneInfo got through the lossy link";
  expect_haptic_rate_held(s);
}

}  // namespace
}  // namespace surgsim
