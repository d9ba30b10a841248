// The whole haptic tick (input, contacts, force, DDS publication, log) on the shipped liver scene.
#include "haptic_app.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "dds_support.h"
#include "haptic_dds.h"
#include "publisher.h"

#include "haptic_node/dds_write_spy.h"
#include "support/alloc_counter.h"
#include "support/test_domain.h"

namespace surgsim {
namespace {

HapticOptions test_options() {
  setenv("SURGSIM_CONFIG_DIR", SURGSIM_TEST_CONFIG_DIR, 1);
  HapticOptions o;
  o.scene = "liver";
  o.speed = 0;  // max
  o.quiet = true;
  o.cache_dir = SURGSIM_TEST_CACHE_DIR;
  o.domain = test::reserve_test_domain();
  o.rt_priority = 0;
  o.lock_memory = false;
  std::filesystem::create_directories(o.cache_dir);
  return o;
}

// Runs ticks 0..warm-1, then counts the allocations of the remaining ticks.
long allocations_once_warm(HapticApp& app, std::uint64_t warm) {
  for (std::uint64_t k = 0; k < warm; ++k) app.tick(k);
  test::AllocationCounter counter;
  for (std::uint64_t k = warm; k < app.total_ticks(); ++k) app.tick(k);
  return counter.count();
}

TEST(HapticApp, TickAllocatesNothingOnceWarm) {
  HapticOptions o = test_options();
  o.log = ::testing::TempDir() + "/haptic_app_alloc_log.csv";
  HapticApp app(o);
  // Warm up: first contact, first DDS sends, log buffer.
  const std::uint64_t warm = 500;  // the poke reaches the organ at about 1.2 s (tick 370 at 300 Hz)
  EXPECT_EQ(allocations_once_warm(app, warm), 0) << "ticks " << warm << ".." << app.total_ticks();
}

// Two instruments: the shipped grasper and probe, one solve, two force stages, two ForceFeedback writes,
// per-instrument log columns and the v2 recording; warm once the grasper holds (t 1.7 s = tick 510 at 300 Hz), then
// counted over the probe's press and both releases.
TEST(HapticApp, TwoInstrumentTickAllocatesNothingOnceWarm) {
  HapticOptions o = test_options();
  o.scene = "liver_two_tools";
  o.log = ::testing::TempDir() + "/haptic_app_two_log.csv";
  o.record = ::testing::TempDir() + "/haptic_app_two_record.csv";
  HapticApp app(o);
  const std::uint64_t warm = 510;
  EXPECT_EQ(allocations_once_warm(app, warm), 0) << "ticks " << warm << ".." << app.total_ticks();
}

// The intestine scene: mass-spring step, probe force, ContactFrame, ForceFeedback and BodyState every tick.
TEST(HapticApp, IntestineTickAllocatesNothingOnceWarm) {
  HapticOptions o = test_options();
  o.scene = "intestine";
  o.duration = 3.0;  // the push reaches the folds at about 1.9 s
  o.log = ::testing::TempDir() + "/haptic_app_intestine_alloc_log.csv";
  HapticApp app(o);
  const std::uint64_t warm = 200;  // first DDS sends, first self-contacts while the folds fall
  EXPECT_EQ(allocations_once_warm(app, warm), 0) << "ticks " << warm << ".." << app.total_ticks();
}

// Nothing but physics on the loop thread: tick() hands its outputs over and the publisher thread makes
// every DDS write. Every tick's ForceFeedback is written before its ContactFrame (--speed max keeps all of them), the
// intestine's BodyState after both, and finish_publishing() ends with a zero force (seq = last tick + 1). With
// frame_every > 1 (haptic.publish_hz) the ContactFrame and the BodyState go out only on ticks 0, frame_every,
// 2 frame_every, ... and the last; the force still every tick.
void expect_no_dds_write_on_the_loop_thread(const std::string& scene, double duration, bool body,
                                            std::uint64_t frame_every = 1) {
  HapticOptions o = test_options();
  o.scene = scene;
  o.duration = duration;
  o.stats = ::testing::TempDir() + "/haptic_app_publish_stats.json";
  HapticApp app(o);
  test::dds_spy_start();
  for (std::uint64_t k = 0; k < app.total_ticks(); ++k) app.tick(k);  // this thread is the loop
  app.finish_publishing();
  const std::vector<test::DdsWrite> w = test::dds_spy_stop();
  const std::uint64_t n = app.total_ticks();
  long on_loop = 0;
  for (const auto& x : w) on_loop += x.thread == std::this_thread::get_id() ? 1 : 0;
  EXPECT_EQ(on_loop, 0) << "DDS writes made by the loop thread";
  std::size_t i = 0;  // the next write expected
  std::uint64_t frames = 0;
  for (std::uint64_t k = 0; k < n; ++k) {
    ASSERT_LT(i, w.size()) << "tick " << k << ": its force was not written";
    const auto& f = w[i++];
    EXPECT_EQ(f.topic, dds::kForceFeedbackTopic) << "tick " << k << ": the force goes first";
    EXPECT_EQ(f.seq, k);
    if (k % frame_every == 0 || k + 1 == n) {
      ASSERT_LT(i, w.size()) << "tick " << k << ": no ContactFrame";
      EXPECT_EQ(w[i].topic, dds::kContactFrameTopic) << "tick " << k;
      EXPECT_EQ(w[i].seq, k);
      // A one-organ scene: every contact entry is organ 0's.
      for (int organ : w[i].contact_organs) EXPECT_EQ(organ, 0) << "tick " << k;
      ++i;
      ++frames;
      if (body) {
        ASSERT_LT(i, w.size()) << "tick " << k << ": no BodyState";
        EXPECT_EQ(w[i].topic, dds::kBodyStateTopic) << "tick " << k;
        EXPECT_EQ(w[i].seq, k);
        EXPECT_EQ(w[i].organ, 0) << "tick " << k << ": BodyState's key, the one organ's index";
        ++i;
      }
    }
    if (::testing::Test::HasFailure()) break;
  }
  ASSERT_EQ(w.size(), i + 1) << "every tick's topics and the final zero, nothing else";
  EXPECT_EQ(frames, (n - 1) / frame_every + 1 + ((n - 1) % frame_every != 0 ? 1 : 0));
  app.shutdown();
  std::ifstream stats(o.stats);
  ASSERT_TRUE(stats) << o.stats;
  EXPECT_EQ(nlohmann::json::parse(stats)["publisher_thinned"].get<std::uint64_t>(), n - frames);
  const auto& last = w.back();
  EXPECT_EQ(last.topic, dds::kForceFeedbackTopic);
  EXPECT_EQ(last.seq, n);
  EXPECT_EQ(last.force[0], 0.0);
  EXPECT_EQ(last.force[1], 0.0);
  EXPECT_EQ(last.force[2], 0.0);
}

TEST(HapticApp, NoDdsWriteOnTheLoopThreadLiver) { expect_no_dds_write_on_the_loop_thread("liver", 2.0, false); }
TEST(HapticApp, NoDdsWriteOnTheLoopThreadIntestine) { expect_no_dds_write_on_the_loop_thread("intestine", 0.5, true); }

// haptic.publish_hz: the intestine scene at 1 kHz publishing at 250 Hz writes its ContactFrame and BodyState on ticks
// 0, 4, 8, ... and the last one; the force every tick.
TEST(HapticApp, FramesAndBodyStatesAtTheScenesPublishRate) {
  const std::string config = SURGSIM_TEST_CONFIG_DIR;
  std::ifstream in(config + "/intestine.yaml");
  ASSERT_TRUE(in) << config << "/intestine.yaml";
  std::stringstream text;
  text << in.rdbuf();
  std::string yaml = text.str();
  const std::string rate = "haptic:\n  rate_hz: 1000\n";
  const std::string trajectory = "trajectory: trajectories/";
  ASSERT_NE(yaml.find(rate), std::string::npos) << "the shipped intestine scene's haptic block changed";
  ASSERT_NE(yaml.find(trajectory), std::string::npos) << "the shipped intestine scene's trajectory changed";
  yaml.replace(yaml.find(rate), rate.size(), rate + "  publish_hz: 250\n");
  yaml.replace(yaml.find(trajectory), trajectory.size(), "trajectory: " + config + "/trajectories/");
  const std::string path = ::testing::TempDir() + "/haptic_app_publish_rate.yaml";
  std::ofstream(path) << yaml;
  expect_no_dds_write_on_the_loop_thread(path, 0.5, true, 4);    // 500 ticks: 0, 4, ..., 496 and the last, 499
  expect_no_dds_write_on_the_loop_thread(path, 0.501, true, 4);  // 501 ticks: 0, 4, ..., 500 (the last)
}

// SceneInfo (wire v3) of a one-organ scene: one OrganInfo, named after the scene, of the scene's model, whose hashes
// and counts are the whole scene's (the scalar fields).
// Returns the organ's entry (empty on failure).
test::OrganInfoWrite expect_one_organ_scene_info(const std::string& scene, const std::string& model) {
  HapticOptions o = test_options();
  o.scene = scene;
  o.duration = 0.1;
  test::dds_spy_start();
  HapticApp app(o);  // publishes SceneInfo at init
  const std::vector<test::DdsWrite> w = test::dds_spy_stop();
  std::vector<test::DdsWrite> infos;
  for (const auto& x : w) {
    if (x.topic == dds::kSceneInfoTopic) infos.push_back(x);
  }
  EXPECT_EQ(infos.size(), 1u) << "one SceneInfo at init";
  if (infos.size() != 1) return {};
  const test::DdsWrite& info = infos[0];
  EXPECT_EQ(info.organs.size(), 1u) << scene << ": one organ";
  if (info.organs.size() != 1) return {};
  const test::OrganInfoWrite& organ = info.organs[0];
  EXPECT_FALSE(info.scene_name.empty());
  EXPECT_EQ(organ.name, info.scene_name) << "the organ of a one-organ scene is named after the scene";
  EXPECT_EQ(organ.model, model);
  EXPECT_EQ(organ.mesh_hash, info.mesh_hash);
  EXPECT_EQ(organ.tensor_hash, info.tensor_hash);
  EXPECT_EQ(organ.node_count, info.node_count);
  EXPECT_EQ(organ.surface_node_count, info.surface_node_count);
  EXPECT_GT(organ.node_count, 0u);
  return organ;
}

TEST(HapticApp, SceneInfoListsTheOrganOfALiverScene) {
  const test::OrganInfoWrite organ = expect_one_organ_scene_info("liver", "liver");
  // The liver has a tetrahedral mesh and tensors: their hashes are not 0.
  EXPECT_NE(organ.mesh_hash, 0u);
  EXPECT_NE(organ.tensor_hash, 0u);
}
TEST(HapticApp, SceneInfoListsTheOrganOfAnIntestineScene) { expect_one_organ_scene_info("intestine", "intestine"); }

// ContactEntry.organ through the publisher thread and HapticDds::write_frame: each entry of each ContactFrame keeps
// the organ (and node) the loop's record gave it, in order (a scene with several organs tags entries 0..7).
TEST(HapticDds, ContactEntryOrganSurvivesThePublisher) {
  setenv("SURGSIM_CONFIG_DIR", SURGSIM_TEST_CONFIG_DIR, 1);
  dds::DdsOptions options;
  options.domain = test::reserve_test_domain();
  options.profiles_file = std::string(SURGSIM_TEST_CONFIG_DIR) + "/dds/profiles.xml";
  options.name = "surgsim_haptic_dds_organ_test";
  HapticDds dds(options, false, 0x77, 1);
  PublisherOptions popt;
  popt.lossless = true;  // every record written
  test::dds_spy_start();
  {
    Publisher publisher(dds, popt);
    for (std::uint64_t k = 0; k < 3; ++k) {
      TickRecord& r = publisher.begin();
      r.seq = k;
      r.instrument_count = 1;
      r.organ.contact_count = 5;
      for (int l = 0; l < 5; ++l) {
        ContactRecord& c = r.organ.contacts[static_cast<std::size_t>(l)];
        c.node = 100 * static_cast<int>(k) + l;
        c.organ = (static_cast<int>(k) + 2 * l) % static_cast<int>(scene::kMaxOrgans);
      }
      publisher.commit();
    }
    publisher.finish();
  }
  const std::vector<test::DdsWrite> w = test::dds_spy_stop();
  std::uint64_t frames = 0;
  for (const auto& x : w) {
    if (x.topic != dds::kContactFrameTopic) continue;
    const std::uint64_t k = x.seq;
    ASSERT_EQ(x.contact_organs.size(), 5u) << "frame " << k;
    for (int l = 0; l < 5; ++l) {
      EXPECT_EQ(x.contact_nodes[static_cast<std::size_t>(l)], 100 * static_cast<int>(k) + l) << "frame " << k;
      EXPECT_EQ(x.contact_organs[static_cast<std::size_t>(l)], (static_cast<int>(k) + 2 * l) % scene::kMaxOrgans)
          << "frame " << k << " entry " << l;
    }
    ++frames;
  }
  EXPECT_EQ(frames, 3u);
}

}  // namespace
}  // namespace surgsim
