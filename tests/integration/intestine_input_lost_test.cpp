// The intestine scene driven live: the real haptic_node with --scene intestine --input device and the real
// surgsim-device-sim playing the push trajectory. While commands flow the probe pushes the folds and a force goes
// back to the device; when the device stops, after --input-timeout the force sent is exactly zero every tick, the
// tool (the probe's position) is held, nothing turns NaN, the node keeps stepping and publishing and exits cleanly.
// The test watches from outside: the per-tick --log, the stats, and its own DDS reader of ContactFrame,
// ForceFeedback and BodyState on the private domain.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <vector>

#include "surgsim_types.h"
#include "dds_support.h"
#include "force_log.h"
#include "node_test.h"
#include "process.h"

namespace surgsim {
namespace {

namespace fs = std::filesystem;
using eprosima::fastdds::dds::DataReader;
using eprosima::fastdds::dds::DataReaderListener;
using eprosima::fastdds::dds::SampleInfo;
using eprosima::fastrtps::types::ReturnCode_t;
using testing::Process;
using testing::wait_for_text;

Eigen::Vector3d vec(const msg::Vec3& v) { return {v.x(), v.y(), v.z()}; }

struct FrameSeen {
  std::uint64_t seq;
  std::uint64_t stamp_ns;  // CLOCK_MONOTONIC when the node published it
  double sim_time;
  Eigen::Vector3d tip, force;
  std::uint32_t flags;
};
struct ForceSeen {
  std::uint64_t seq;
  Eigen::Vector3d force;
  std::uint32_t flags;
};
struct BodySeen {
  std::uint64_t seq;
  bool finite;
  Eigen::Vector3d tip;
};

// Everything the haptic node publishes, as the test receives it (DDS listener thread; read after the run).
class Recorder : public DataReaderListener {
 public:
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    const std::string topic = reader->get_topicdescription()->get_name();
    std::lock_guard<std::mutex> lock(mutex);
    if (topic == dds::kContactFrameTopic) {
      while (reader->take_next_sample(&frame_, &info) == ReturnCode_t::RETCODE_OK) {
        if (info.valid_data) {
          const msg::InstrumentState& in = frame_.instruments().at(0);  // the scene's one instrument
          frames.push_back({frame_.seq(), frame_.stamp_ns(), frame_.sim_time(), vec(in.tip()), vec(in.force()),
                            frame_.flags()});
        }
      }
    } else if (topic == dds::kForceFeedbackTopic) {
      while (reader->take_next_sample(&force_, &info) == ReturnCode_t::RETCODE_OK) {
        if (info.valid_data) forces.push_back({force_.seq(), vec(force_.force()), force_.flags()});
      }
    } else if (topic == dds::kToolCommandTopic) {
      while (reader->take_next_sample(&command_, &info) == ReturnCode_t::RETCODE_OK) {
        if (info.valid_data) last_command_ns = std::max(last_command_ns, command_.stamp_ns());
      }
    } else {
      while (reader->take_next_sample(&body_, &info) == ReturnCode_t::RETCODE_OK) {
        if (!info.valid_data) continue;
        bool finite = !body_.positions().empty();
        for (const auto& p : body_.positions()) finite = finite && std::isfinite(p.x()) && std::isfinite(p.y()) &&
                                                         std::isfinite(p.z());
        bodies.push_back({body_.seq(), finite, vec(body_.instruments().at(0).tip())});
      }
    }
  }
  std::mutex mutex;
  std::vector<FrameSeen> frames;
  std::vector<ForceSeen> forces;
  std::vector<BodySeen> bodies;
  std::uint64_t last_command_ns = 0;  // the device's stamp (CLOCK_MONOTONIC) of its last ToolCommand

 private:
  msg::ToolCommand command_;
  msg::ContactFrame frame_;
  msg::ForceFeedback force_;
  msg::BodyState body_;
};

class IntestineInputLost : public testing::NodeTest {
 protected:
  void SetUp() override { prepare("intestine_lost", 17); }
};

TEST_F(IntestineInputLost, DeviceStopsMidPushForceZeroProbeHeldNodeRunsOn) {
  // The test's own reader of what the haptic node publishes.
  dds::DdsOptions o;
  o.domain = domain_;
  o.profiles_file = std::string(SURGSIM_TEST_CONFIG_DIR) + "/dds/profiles.xml";
  o.name = "surgsim_test_observer";
  Recorder seen;
  dds::Participant p(o);
  p.reader(p.topic(dds::kContactFrameTopic, new msg::ContactFramePubSubType()), dds::kContactReader, &seen);
  p.reader(p.topic(dds::kForceFeedbackTopic, new msg::ForceFeedbackPubSubType()), dds::kStreamReader, &seen);
  p.reader(p.topic(dds::kBodyStateTopic, new msg::BodyStatePubSubType()), dds::kStreamReader, &seen);
  p.reader(p.topic(dds::kToolCommandTopic, new msg::ToolCommandPubSubType()), dds::kStreamReader, &seen);

  // The device plays intestine_push (the tip reaches the folds at about 1.9 s and pushes 1-2 N until 3.8 s) and
  // stops by itself at 3.0 s of its motion, mid-push; the haptic node runs on for 7 s in all.
  const double timeout_s = 0.1;
  Process haptic(bin("haptic_node"),
                 {"--scene", "intestine", "--input", "device", "--input-timeout", "0.1", "--duration", "7",
                  "--rt-priority", "0", "--no-mlock", "--stats", path("haptic.json"), "--log", path("haptic.csv")},
                 env_, path("haptic.log"));
  // The device starts once this test's readers see the node's topics (on a loaded machine discovery can take
  // longer than the device's 3 s of motion).
  const std::uint64_t until = testing::now_ns() + 60'000'000'000ull;
  for (bool matched = false; !matched && testing::now_ns() < until;) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    std::lock_guard<std::mutex> lock(seen.mutex);
    matched = !seen.frames.empty() && !seen.forces.empty() && !seen.bodies.empty();
  }
  Process device(bin("surgsim-device-sim"),
                 {"--trajectory", std::string(SURGSIM_TEST_CONFIG_DIR) + "/trajectories/intestine_push.csv", "--rate",
                  "1000", "--duration", "3.0", "--wait-for-haptic", "60", "--stats", path("device.json")},
                 env_, path("device.log"));
  ASSERT_TRUE(wait_for_text(path("device.log"), "haptic node matched", 60)) << testing::read_file(path("device.log"));
  ASSERT_EQ(device.wait(60), 0) << testing::read_file(path("device.log"));
  ASSERT_EQ(haptic.wait(120), 0) << testing::read_file(path("haptic.log"));
  std::this_thread::sleep_for(std::chrono::milliseconds(200));  // the last samples in flight

  // Stats: the whole run stepped the intestine without a fault; input was used, then lost.
  const auto h = nlohmann::json::parse(testing::read_file(path("haptic.json")));
  const double rate = h["rate_hz"].get<double>();
  EXPECT_EQ(h["ticks"].get<double>(), 7.0 * rate) << "the node ran to its end after the device stopped";
  EXPECT_EQ(h["model_built"], "intestine");
  EXPECT_EQ(h["input"], "device");
  EXPECT_GT(h["commands_received"].get<double>(), 1000.0);
  EXPECT_GT(h["input_lost_ticks"].get<double>(), 2.0 * rate) << "lost from the device's stop to the end";
  EXPECT_EQ(h["nonfinite_rejected"].get<int>(), 0);
  EXPECT_EQ(h["intestine"]["faults"].get<int>(), 0);
  EXPECT_TRUE(h["intestine"]["positions_finite"].get<bool>());
  EXPECT_EQ(h["intestine"]["steps"].get<double>(), 7.0 * rate);
  EXPECT_EQ(h["intestine"]["body_states_published"].get<double>(), 7.0 * rate);

  // The device got the force back while it pushed.
  const auto d = nlohmann::json::parse(testing::read_file(path("device.json")));
  EXPECT_GT(d["forces_received"].get<double>(), 1000.0);
  EXPECT_GT(d["force_max_n"].get<double>(), 0.3) << "force fed back to the device while commands flowed";
  EXPECT_EQ(d["nonfinite"].get<int>(), 0);

  // What the node published, as received here.
  std::lock_guard<std::mutex> lock(seen.mutex);
  ASSERT_GT(seen.frames.size(), static_cast<std::size_t>(rate)) << "contact frames received";
  // The last frame of live input, then the frames of the loss after it.
  std::uint64_t last_fresh = 0;
  bool any_fresh = false;
  for (const auto& f : seen.frames) {
    if ((f.flags & msg::kFlagInputLost) == 0) {
      last_fresh = std::max(last_fresh, f.seq);
      any_fresh = true;
    }
  }
  ASSERT_TRUE(any_fresh);
  Eigen::Vector3d held = Eigen::Vector3d::Constant(std::nan("")), fresh_tip = held;
  double last_fresh_time = 0;
  std::uint64_t last_fresh_stamp = 0;
  long lost_frames = 0, moved = 0, lost_with_force = 0, fresh_after_loss = 0;
  for (const auto& f : seen.frames) {
    ASSERT_TRUE(f.tip.allFinite() && f.force.allFinite()) << "frame " << f.seq;
    if (f.seq == last_fresh) {
      fresh_tip = f.tip;
      last_fresh_time = f.sim_time;
      last_fresh_stamp = f.stamp_ns;
    }
    if (f.seq <= last_fresh) continue;
    if ((f.flags & msg::kFlagInputLost) == 0) ++fresh_after_loss;
    ++lost_frames;
    if (!held.allFinite()) held = f.tip;
    if (f.tip != held) ++moved;
    if (f.force != Eigen::Vector3d::Zero()) ++lost_with_force;
  }
  // Live input lasted until the device's last command and --input-timeout after it (both stamps on the monotonic
  // clock: the node's simulated time lags the wall clock when a loaded machine slows its loop).
  ASSERT_GT(seen.last_command_ns, 0u) << "no ToolCommand seen";
  const double live_after_s = (static_cast<double>(last_fresh_stamp) - static_cast<double>(seen.last_command_ns)) * 1e-9;
  EXPECT_GT(live_after_s, -0.3) << "input counted as lost well before the device stopped";
  // A functional bound (a stalled loop or DDS thread on a loaded machine delays both stamps' gap a little).
  EXPECT_LT(live_after_s, timeout_s + 1.0) << "live input used long after the device's last command";
  EXPECT_GT(lost_frames, static_cast<long>(rate)) << "contact frames kept coming after the loss";
  EXPECT_EQ(fresh_after_loss, 0);
  EXPECT_EQ(moved, 0) << "the tool moved while the input was lost";
  EXPECT_EQ(lost_with_force, 0) << "a lost-input frame carried a force";
  // Held where the last command put it (the frames between are a tick or two of the slow push apart).
  EXPECT_LT((held - fresh_tip).norm(), 0.002) << "held " << held.transpose() << ", last live " << fresh_tip.transpose();

  // ForceFeedback after the loss: flagged and exactly zero.
  long lost_forces = 0, lost_nonzero = 0;
  for (const auto& f : seen.forces) {
    ASSERT_TRUE(f.force.allFinite());
    if (f.seq <= last_fresh) continue;
    ++lost_forces;
    if ((f.flags & msg::kFlagInputLost) == 0 || f.force != Eigen::Vector3d::Zero()) ++lost_nonzero;
  }
  EXPECT_GT(lost_forces, static_cast<long>(rate));
  EXPECT_EQ(lost_nonzero, 0);

  // BodyState: finite throughout, still published after the loss, with the held tip.
  long bodies_after = 0, bodies_bad = 0;
  for (const auto& b : seen.bodies) {
    if (!b.finite) ++bodies_bad;
    if (b.seq > last_fresh) {
      ++bodies_after;
      if (b.tip != held) ++bodies_bad;
    }
  }
  EXPECT_EQ(bodies_bad, 0);
  EXPECT_GT(bodies_after, static_cast<long>(rate));

  // The per-tick log, on the node's simulated time: the probe pushed until the last live tick; from
  // --input-timeout after it (50 ms of margin for a frame of live input this test did not receive) to the end the
  // force is exactly zero.
  const testing::ForceAroundLoss f =
      testing::force_around_loss(path("haptic.csv"), last_fresh_time, 0.5, timeout_s + 0.05);
  EXPECT_EQ(f.rows, static_cast<long>(7.0 * rate));
  EXPECT_TRUE(f.finite);
  EXPECT_GT(f.before_max, 0.05) << "the probe pushed the folds when the device stopped";
  ASSERT_GE(f.first_zero_after, 0.0) << "the force never went to zero after the device stopped";
  EXPECT_LE(f.first_zero_after - last_fresh_time, timeout_s + 0.05);
  EXPECT_EQ(f.nonzero_late, 0) << "no stale force after the loss";
  EXPECT_GT(f.zero_late, static_cast<long>(rate));
}

}  // namespace
}  // namespace surgsim
