// DDS Security: with the credentials of scripts/make_dds_security.sh (test CA, PKI-DH authentication,
// signed governance and permissions, AES-GCM), the secure nodes talk; a participant without credentials on the same
// domain can neither read contact frames nor inject tool commands; an authenticated identity cannot use a topic its
// permissions do not grant.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>

#include "process.h"
#include "support/test_domain.h"

namespace surgsim {
namespace {

namespace fs = std::filesystem;
using testing::Process;

class Security : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::path(::testing::TempDir()) / ("surgsim_security_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    Process make("/bin/bash",
                 {std::string(SURGSIM_TEST_CONFIG_DIR) + "/../scripts/make_dds_security.sh", (dir_ / "sec").string()},
                 {}, (dir_ / "make.log").string());
    made_ = make.wait(60) == 0;
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }
  void SetUp() override {
    ASSERT_TRUE(made_) << testing::read_file((dir_ / "make.log").string());
    env_ = {"SURGSIM_DOMAIN=" + std::to_string(test::reserve_test_domain(23)),
            "SURGSIM_CONFIG_DIR=" SURGSIM_TEST_CONFIG_DIR, "SURGSIM_CACHE_DIR=" SURGSIM_TEST_CACHE_DIR,
            "FASTRTPS_DEFAULT_PROFILES_FILE=" + (dir_ / "sec" / "secure_profiles.xml").string()};
  }
  std::string bin(const std::string& name) const { return std::string(SURGSIM_TEST_BIN_DIR) + "/" + name; }
  static std::string path(const std::string& name) { return (dir_ / name).string(); }
  static nlohmann::json json(const std::string& name) { return nlohmann::json::parse(testing::read_file(path(name))); }
  static inline fs::path dir_;
  static inline bool made_ = false;
  std::vector<std::string> env_;
};

TEST_F(Security, UnauthenticatedParticipantCanNeitherReadNorInject) {
  // Secure: haptic node (live device input), visual node, device (insertion 0.12 +- 0.02 m).
  // Without credentials (surgsim_udp, same domain): a visual node, and a device commanding insertion 0.30 m.
  Process visual(bin("visual_node"),
                 {"--headless", "--dds-participant", "surgsim_secure_visual", "--stats", path("visual.json")}, env_,
                 path("visual.log"));
  Process spy(bin("visual_node"), {"--headless", "--dds-participant", "surgsim_udp", "--stats", path("spy.json")},
              env_, path("spy.log"));
  Process haptic(bin("haptic_node"),
                 {"--dds-participant", "surgsim_secure_haptic", "--input", "device", "--duration", "3",
                  "--wait-for-visual", "60", "--rt-priority", "0", "--record", path("used.csv"), "--stats",
                  path("haptic.json")},
                 env_, path("haptic.log"));
  Process rogue(bin("surgsim-device-sim"),
                {"--dds-participant", "surgsim_udp", "--depth", "0.30", "--duration", "4", "--stats", path("rogue.json")},
                env_, path("rogue.log"));
  Process device(bin("surgsim-device-sim"),
                 {"--dds-participant", "surgsim_secure_device", "--depth", "0.12", "--duration", "4",
                  "--wait-for-haptic", "60", "--stats", path("device.json")},
                 env_, path("device.log"));
  ASSERT_EQ(haptic.wait(90), 0) << testing::read_file(path("haptic.log"));
  ASSERT_EQ(device.wait(30), 0) << testing::read_file(path("device.log"));
  ASSERT_EQ(rogue.wait(30), 0) << testing::read_file(path("rogue.log"));
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  visual.signal(SIGINT);
  spy.signal(SIGINT);
  ASSERT_EQ(visual.wait(30), 0) << testing::read_file(path("visual.log"));
  ASSERT_EQ(spy.wait(30), 0) << testing::read_file(path("spy.log"));

  // The secure nodes talk (authenticated, encrypted): frames, scene info, commands, forces.
  const auto h = json("haptic.json");
  const auto v = json("visual.json");
  const auto d = json("device.json");
  EXPECT_GT(v["frames_received"].get<double>(), 0.5 * h["ticks"].get<double>()) << v.dump(2);
  EXPECT_TRUE(v["scene_hash_ok"].get<bool>());
  EXPECT_GT(h["commands_received"].get<double>(), 100.0) << h.dump(2);
  EXPECT_GT(d["forces_received"].get<double>(), 100.0) << d.dump(2);
  // Without credentials: nothing read, nothing injected.
  const auto s = json("spy.json");
  EXPECT_EQ(s["frames_received"].get<int>(), 0) << s.dump(2);
  EXPECT_FALSE(s["scene_info_received"].get<bool>());
  const auto r = json("rogue.json");
  EXPECT_GT(r["commands_sent"].get<double>(), 1000.0);
  EXPECT_EQ(r["forces_received"].get<int>(), 0);
  // Every pose the haptic node used came from the secure device (insertion <= 0.14 m), none from the rogue (0.28+).
  std::istringstream used(testing::read_file(path("used.csv")));
  std::string line;
  int poses = 0;
  double max_insertion = 0;
  while (std::getline(used, line)) {
    if (line.empty() || line[0] == '#' || line[0] == 't') continue;
    std::stringstream ss(line);
    std::string f[4];
    for (auto& x : f) std::getline(ss, x, ',');
    max_insertion = std::max(max_insertion, std::stod(f[3]));
    ++poses;
  }
  EXPECT_GT(poses, 100);
  EXPECT_LT(max_insertion, 0.15) << "a tool command from the participant without credentials was used";
}

TEST_F(Security, PermissionsLimitAnAuthenticatedIdentity) {
  // The device's identity is authenticated but may not subscribe to scene info or contact frames: a visual node
  // started with it cannot create its readers and stops with the reason.
  Process wrong(bin("visual_node"), {"--headless", "--dds-participant", "surgsim_secure_device"}, env_,
                path("wrong.log"));
  EXPECT_EQ(wrong.wait(60), 1);
  EXPECT_NE(testing::read_file(path("wrong.log")).find("cannot create a DDS reader on surgsim/"), std::string::npos)
      << testing::read_file(path("wrong.log"));
}

}  // namespace
}  // namespace surgsim
