// The real visual_node process driven by this test's own DDS participant: the test stands in for
// the haptic node, publishing SceneInfo and ContactFrames with the generated types, and reads the node's
// VisualStatus back.
//  - VisualStatus.fps is the measured frame rate, not the configured one: with a --rate the OSMesa renderer cannot
//    keep up with, the fps the node sends matches frames_rendered / time as seen in the status samples themselves.
//  - Contact frames are not drawn before SceneInfo confirmed the scene, and a frame whose scene_hash is not the
//    node's is never drawn, but counted (stats frames_wrong_scene) with one stderr line naming both hashes.
//  - Several instruments: a SceneInfo whose instrument_count is not the scene's tool count refuses the
//    frames (one stderr line naming the scene file, exit 3); in a two-tool scene every frame draws both instruments,
//    each in its own colour, in the PNGs the node writes, and states of instruments the scene lacks are ignored.
// The frame the node draws is VisualStatus.last_seq_shown of its per-frame status (echoed_stamp_ns == 0; the echo
// the node sends on each frame's arrival has echoed_stamp_ns != 0 and proves the frame arrived).
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <fstream>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "surgsim_types.h"
#include "core/clock.h"
#include "dds_support.h"
#include "node_test.h"
#include "organ_view.h"
#include "process.h"
#include "render/image.h"
#include "render/renderer.h"
#include "scene/scene.h"
#include "tool/tool.h"
#include "views/liver_view.h"

using namespace surgsim::core;
using namespace surgsim::tool;
using namespace surgsim::scene;

namespace surgsim {
namespace {

using eprosima::fastdds::dds::DataReader;
using eprosima::fastdds::dds::DataReaderListener;
using eprosima::fastdds::dds::DataWriter;
using eprosima::fastdds::dds::SampleInfo;
using eprosima::fastrtps::types::ReturnCode_t;
using testing::Process;
using testing::wait_until;

struct StatusSeen {
  std::uint64_t stamp_ns;
  double fps;
  std::uint64_t last_seq_shown;
  std::uint64_t echoed_stamp_ns;
  std::uint64_t frames_rendered;
};

// Every VisualStatus the node sends, as received here (DDS listener thread).
class StatusRecorder : public DataReaderListener {
 public:
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    while (reader->take_next_sample(&sample_, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      std::lock_guard<std::mutex> lock(mutex);
      seen.push_back({sample_.stamp_ns(), sample_.fps(), sample_.last_seq_shown(), sample_.echoed_stamp_ns(),
                      sample_.frames_rendered()});
    }
  }
  /// Per-frame statuses (not echoes).
  std::vector<StatusSeen> frames() {
    std::lock_guard<std::mutex> lock(mutex);
    std::vector<StatusSeen> out;
    for (const auto& s : seen)
      if (s.echoed_stamp_ns == 0) out.push_back(s);
    return out;
  }
  /// Echoed sequence numbers (frames that reached the node).
  std::vector<std::uint64_t> echoed() {
    std::lock_guard<std::mutex> lock(mutex);
    std::vector<std::uint64_t> out;
    for (const auto& s : seen)
      if (s.echoed_stamp_ns != 0) out.push_back(s.last_seq_shown);
    return out;
  }
  std::uint64_t max_frames_rendered() {
    std::lock_guard<std::mutex> lock(mutex);
    std::uint64_t m = 0;
    for (const auto& s : seen) m = std::max(m, s.frames_rendered);
    return m;
  }
  std::mutex mutex;
  std::vector<StatusSeen> seen;

 private:
  msg::VisualStatus sample_;
};

class VisualNode : public testing::NodeTest {
 protected:
  void SetUp() override {
    prepare("visual_node", 29);
    dds::DdsOptions o;
    o.domain = domain_;
    o.profiles_file = std::string(SURGSIM_TEST_CONFIG_DIR) + "/dds/profiles.xml";
    o.name = "surgsim_test_fake_haptic";
    participant_ = std::make_unique<dds::Participant>(o);
    auto& p = *participant_;
    p.reader(p.topic(dds::kVisualStatusTopic, new msg::VisualStatusPubSubType()), dds::kStreamReader, &status_);
    frame_writer_ = p.writer(p.topic(dds::kContactFrameTopic, new msg::ContactFramePubSubType()), dds::kContactWriter);
    scene_writer_ = p.writer(p.topic(dds::kSceneInfoTopic, new msg::SceneInfoPubSubType()), dds::kLatchedWriter);
  }
  void TearDown() override {
    participant_.reset();
    NodeTest::TearDown();
  }

  /// Until the node's status arrives and its contact reader matched the test's writer.
  bool node_ready(double timeout_s) {
    return wait_until(
        [&] {
          eprosima::fastdds::dds::PublicationMatchedStatus st;
          frame_writer_->get_publication_matched_status(st);
          return st.current_count > 0 && status_.max_frames_rendered() > 0;
        },
        timeout_s);
  }
  /// Until the node has rendered `n` more frames than now (so it has looked at what arrived by now).
  bool frames_pass(std::uint64_t n, double timeout_s) {
    const std::uint64_t from = status_.max_frames_rendered();
    return wait_until([&] { return status_.max_frames_rendered() >= from + n; }, timeout_s);
  }
  /// Writes `frame` as seq first..last (100 Hz) with `scene_hash`; true once the node echoed one of them.
  bool publish(msg::ContactFrame& frame, std::uint64_t first, std::uint64_t last, std::uint64_t scene_hash) {
    for (std::uint64_t seq = first; seq <= last; ++seq) {
      frame.seq(seq);
      frame.stamp_ns(monotonic_ns());
      frame.scene_hash(scene_hash);
      frame.sim_time(static_cast<double>(seq) * 1e-3);
      frame_writer_->write(&frame);
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return wait_until(
        [&] {
          const auto e = status_.echoed();
          return std::any_of(e.begin(), e.end(), [&](std::uint64_t s) { return s >= first && s <= last; });
        },
        30);
  }
  /// Per-frame statuses whose frame shown is one of seq first..last.
  long shown_in(std::uint64_t first, std::uint64_t last) {
    long n = 0;
    for (const auto& s : status_.frames()) n += s.last_seq_shown >= first && s.last_seq_shown <= last;
    return n;
  }
  /// The SceneInfo a haptic node running `scene` sends (`hash`: its identity with the mesh; `instruments` its count).
  void publish_scene_info(const Scene& scene, const OrganView& view, std::uint64_t hash, std::uint32_t instruments) {
    msg::SceneInfo info;
    info.scene_name(scene.name);
    info.scene_hash(hash);
    info.mesh_hash(view.mesh_hash());
    info.tensor_hash(view.tensor_hash());
    info.instrument_count(instruments);
    info.start_stamp_ns(monotonic_ns());
    scene_writer_->write(&info);
  }

  std::unique_ptr<dds::Participant> participant_;
  StatusRecorder status_;
  DataWriter* frame_writer_ = nullptr;
  DataWriter* scene_writer_ = nullptr;
};

// A liver-model scene as the node will load it: its scene identity, its view (mesh, tensors) and a visible node to
// press.
struct LiverScene {
  explicit LiverScene(const std::string& file) : scene(load_scene(file)) {
    OrganViewOptions vo;
    vo.cache_dir = SURGSIM_TEST_CACHE_DIR;
    view = make_organ_view(scene, vo);
    hash = visual_scene_hash(scene, view->mesh_hash());
    const auto& visible = dynamic_cast<const LiverView&>(*view).deformer().visible_nodes();
    node = visible[visible.size() / 2];
  }
  Scene scene;
  std::unique_ptr<OrganView> view;
  std::uint64_t hash = 0;
  int node = 0;
};

// One instrument's state in a contact frame: its pose (pitch, insertion), pressing down.
msg::InstrumentState instrument_state(std::uint32_t index, double insertion, double pitch = 0) {
  msg::InstrumentState s;
  s.instrument(index);
  s.pose().insertion(insertion);
  s.pose().pitch(pitch);
  s.direction().z(-1);
  return s;
}

// A frame of the one-tool liver: instrument 0 pressing `node` down.
msg::ContactFrame one_contact_frame(int node) {
  msg::ContactFrame frame;
  frame.contacts().resize(1);
  frame.contacts()[0].node(static_cast<std::uint32_t>(node));
  frame.contacts()[0].instrument(0);
  frame.contacts()[0].lambda().z(-0.5);
  frame.instruments().push_back(instrument_state(0, 0.15));
  return frame;
}

TEST_F(VisualNode, SendsTheMeasuredFrameRateNotTheConfiguredOne) {
  // OSMesa at a rate no renderer reaches (one frame per 10 us): the loop renders back to back, as fast as it can.
  const double configured = 100000;
  Process visual(bin("visual_node"),
                 {"--scene", "liver", "--rate", std::to_string(configured), "--png-every", "0", "--out",
                  path("frames"), "--stats", path("visual.json")},
                 env_, path("visual.log"));
  ASSERT_TRUE(node_ready(120)) << testing::read_file(path("visual.log"));
  // At least 2 s of the node's own statuses (its rate window is 1 s) and 20 frames.
  ASSERT_TRUE(wait_until(
      [&] {
        const auto f = status_.frames();
        return f.size() >= 20 && f.back().stamp_ns - f.front().stamp_ns > 2'000'000'000ull;
      },
      120))
      << testing::read_file(path("visual.log"));
  visual.signal(SIGINT);
  ASSERT_EQ(visual.wait(60), 0) << testing::read_file(path("visual.log"));

  // The rate in the samples themselves: frames_rendered over the node's stamps, over the last second before each
  // sample; the fps the node sent with that sample must match it (the same window, up to a status' few us).
  const auto f = status_.frames();
  ASSERT_GE(f.size(), 20u);
  int compared = 0, mismatched = 0;
  std::string first_mismatch;
  for (std::size_t b = 0; b < f.size(); ++b) {
    if (f[b].stamp_ns - f.front().stamp_ns < 1'200'000'000ull) continue;  // a full window behind it
    std::size_t a = b;
    while (a > 0 && f[b].stamp_ns - f[a - 1].stamp_ns <= 1'000'000'000ull) --a;
    if (a == b || f[b].frames_rendered - f[a].frames_rendered < 5) continue;  // too few frames seen in the window
    const double seen = static_cast<double>(f[b].frames_rendered - f[a].frames_rendered) /
                        (static_cast<double>(f[b].stamp_ns - f[a].stamp_ns) * 1e-9);
    ++compared;
    // Within a factor of 2: the node's window ends at its newest frame, the test's between two statuses, so on a
    // loaded machine (ctest -j2 beside the DDS security tests) a stall of the process falls in one and not the other
    // (a fresh-clone run saw 360 sent against 238 between statuses, with 15 % allowed). The mistake this catches is
    // of another order: the configured 100000 fps sent for a few hundred rendered.
    if ((f[b].fps > 2 * seen + 1.0 || f[b].fps < seen / 2 - 1.0) && mismatched++ == 0) {
      first_mismatch = "status of frame " + std::to_string(f[b].frames_rendered) + ": sent " +
                       std::to_string(f[b].fps) + " fps, rendered " + std::to_string(seen) + " fps, configured " +
                       std::to_string(configured);
    }
  }
  EXPECT_GT(compared, 0) << "no status with a full window of frames before it";
  EXPECT_EQ(mismatched, 0) << mismatched << " of " << compared << " statuses sent another rate than rendered; first: "
                           << first_mismatch;

  // And the run's average from the stats: the same order as the rate sent (whatever the machine's speed).
  const auto v = json(path("visual.json"));
  const double average = v["fps"].get<double>();
  EXPECT_EQ(v["fps_configured"].get<double>(), configured);
  ASSERT_GT(average, 0);
  EXPECT_LT(f.back().fps, 3 * average + 1) << "sent " << f.back().fps << ", run average " << average;
  EXPECT_GT(f.back().fps, average / 3 - 1) << "sent " << f.back().fps << ", run average " << average;
}

TEST_F(VisualNode, DrawsOnlyFramesOfTheConfirmedScene) {
  const LiverScene liver(std::string(SURGSIM_TEST_CONFIG_DIR) + "/liver.yaml");
  const Scene& scene = liver.scene;
  const std::uint64_t hash = liver.hash;
  const std::uint64_t wrong_hash = hash ^ 0x5a5a5a5aull;

  Process visual(bin("visual_node"), {"--scene", "liver", "--headless", "--stats", path("visual.json")}, env_,
                 path("visual.log"));
  ASSERT_TRUE(node_ready(120)) << testing::read_file(path("visual.log"));

  msg::ContactFrame frame = one_contact_frame(liver.node);

  // 1. Frames of the right scene but no SceneInfo yet: they arrive, none is drawn.
  ASSERT_TRUE(publish(frame, 1, 60, hash)) << "the node never received a frame\n"
                                           << testing::read_file(path("visual.log"));
  ASSERT_TRUE(frames_pass(5, 60));
  EXPECT_EQ(shown_in(1, 1000000), 0) << "a frame was drawn before SceneInfo confirmed the scene";

  // 2. SceneInfo confirms the scene: the newest frame waiting is drawn.
  publish_scene_info(scene, *liver.view, hash, 1);
  EXPECT_TRUE(wait_until([&] { return shown_in(1, 60) > 0; }, 60))
      << "the waiting frame was not drawn after SceneInfo\n" << testing::read_file(path("visual.log"));

  // 3. Frames of another scene: they arrive, none is drawn.
  ASSERT_TRUE(publish(frame, 1001, 1060, wrong_hash));
  ASSERT_TRUE(frames_pass(5, 60));
  EXPECT_EQ(shown_in(1001, 1060), 0) << "a frame of another scene (scene_hash) was drawn";

  // 4. Frames of this scene again: drawn.
  ASSERT_TRUE(publish(frame, 2001, 2060, hash));
  EXPECT_TRUE(wait_until([&] { return shown_in(2001, 2060) > 0; }, 60)) << testing::read_file(path("visual.log"));

  visual.signal(SIGINT);
  ASSERT_EQ(visual.wait(60), 0) << testing::read_file(path("visual.log"));
  const std::string log = testing::read_file(path("visual.log"));
  const auto v = json(path("visual.json"));
  long wrong_echoed = 0;
  for (std::uint64_t s : status_.echoed()) wrong_echoed += s >= 1001 && s <= 1060;
  EXPECT_GE(v.value("frames_wrong_scene", -1L), std::max(1L, wrong_echoed)) << v.dump();
  EXPECT_LE(v.value("frames_wrong_scene", -1L), 60L);
  EXPECT_GE(v.value("frames_before_scene_info", -1L), 1L) << v.dump();
  EXPECT_LE(v.value("frames_before_scene_info", -1L), 60L);
  EXPECT_TRUE(v.value("scene_confirmed", false));
  // Deformation ran only for the frames drawn (the waiting one and phase 4's).
  EXPECT_GE(v.value("frames_shown", -1L), 2L);
  EXPECT_EQ(v["deform_us"]["count"].get<long>(), v.value("frames_shown", -1L));
  EXPECT_EQ(v["deform_errors"].get<long>(), 0);
  // One stderr line naming both hashes.
  const std::string line = "contact frame with scene hash " + std::to_string(wrong_hash);
  const auto at = log.find(line);
  ASSERT_NE(at, std::string::npos) << log;
  EXPECT_NE(log.substr(at, log.find('\n', at) - at).find(std::to_string(hash)), std::string::npos) << log;
  EXPECT_EQ(log.find(line, at + 1), std::string::npos) << "one line per foreign hash\n" << log;
}

// A haptic node that drives another number of instruments than the scene has tools: its frames are never
// drawn, one stderr line names both counts and this node's scene file, and the node exits with 3 as for a foreign
// scene.
TEST_F(VisualNode, RefusesFramesWhenTheInstrumentCountDiffers) {
  const LiverScene liver(std::string(SURGSIM_TEST_CONFIG_DIR) + "/liver.yaml");
  const Scene& scene = liver.scene;
  ASSERT_EQ(scene.tools.size(), 1u);

  Process visual(bin("visual_node"), {"--scene", "liver", "--headless", "--stats", path("visual.json")}, env_,
                 path("visual.log"));
  ASSERT_TRUE(node_ready(120)) << testing::read_file(path("visual.log"));
  publish_scene_info(scene, *liver.view, liver.hash, 2);  // the same scene and tensors, but two instruments
  msg::ContactFrame frame = one_contact_frame(liver.node);
  frame.instruments().push_back(instrument_state(1, 0.1));
  ASSERT_TRUE(publish(frame, 1, 60, liver.hash)) << testing::read_file(path("visual.log"));
  ASSERT_TRUE(frames_pass(10, 60));
  EXPECT_EQ(shown_in(1, 60), 0) << "a frame was drawn although the instrument counts differ";

  visual.signal(SIGINT);
  EXPECT_EQ(visual.wait(60), 3) << testing::read_file(path("visual.log"));
  const std::string log = testing::read_file(path("visual.log"));
  const auto at = log.find("the haptic node drives 2 instrument(s)");
  ASSERT_NE(at, std::string::npos) << log;
  const std::string line = log.substr(at, log.find('\n', at) - at);
  EXPECT_NE(line.find(scene.file), std::string::npos) << "the line names the scene file: " << line;
  EXPECT_NE(line.find("has 1 ('tool')"), std::string::npos) << line;
  EXPECT_EQ(log.find("the haptic node drives", at + 1), std::string::npos) << "said once\n" << log;
  const auto v = json(path("visual.json"));
  EXPECT_FALSE(v.value("scene_confirmed", true));
  EXPECT_FALSE(v.value("instrument_count_ok", true));
  EXPECT_TRUE(v.value("scene_hash_ok", false));
  EXPECT_EQ(v.value("frames_shown", -1L), 0L);
  EXPECT_EQ(v.value("instruments", -1L), 1L);
}

// A scene with two instruments (a `tools:` list): every frame draws both, each from its own tool spec and in its own
// colour (instrument 0 grey, instrument 1 blue), in the PNG the node writes; frames.csv says 2 instruments; a state
// naming an instrument the scene does not have is ignored, counted and named once on stderr.
TEST_F(VisualNode, DrawsEveryInstrumentOfATwoToolScene) {
  const std::string config = SURGSIM_TEST_CONFIG_DIR;
  const std::string scene_file = path("two_tools.yaml");
  {
    // The shipped liver (same mesh, material, fixed set and law: the cached tensors) with two instruments and a
    // small picture, every frame written.
    std::ofstream f(scene_file);
    f << "name: liver_two_tools_test\n"
         "model: liver\n"
         "mesh: {generate: liver, target_nodes: 1500}\n"
         "material: {young_modulus: 3000.0, poisson_ratio: 0.45}\n"
         "nonlinear: {displacement_curve: " << config << "/curves/liver_dr.csv, force_curve: " << config
      << "/curves/liver_force.csv, degree: 6}\n"
         "fixed: {plane: {point: [0, 0, -0.025], normal: [0, 0, -1]}}\n"
         "tools:\n"
         "  - {name: grasper, trocar: [0.03, 0.0, 0.15], axis: [0, 0, -1]}\n"
         "  - {name: probe, trocar: [-0.07, 0.02, 0.15], axis: [0, 0, -1], shaft_radius: 0.003}\n"
         "visual:\n"
         "  width: 320\n"
         "  height: 240\n"
         "  camera: {eye: [0.17, -0.24, 0.19], target: [0.01, 0.0, 0.0], up: [0, 0, 1], fov_deg: 35}\n"
         "  png_every: 1\n";
  }
  const LiverScene liver(scene_file);
  const Scene& scene = liver.scene;
  ASSERT_EQ(scene.tools.size(), 2u);

  Process visual(bin("visual_node"), {"--scene", scene_file, "--out", path("frames"), "--stats", path("visual.json")},
                 env_, path("visual.log"));
  ASSERT_TRUE(node_ready(120)) << testing::read_file(path("visual.log"));
  publish_scene_info(scene, *liver.view, liver.hash, 2);

  // Instrument 0 straight down towards the organ, instrument 1 tilted; a state of a fourth instrument the scene
  // does not have; one contact of instrument 0.
  msg::ContactFrame frame = one_contact_frame(liver.node);
  frame.instruments().clear();
  const msg::InstrumentState grasper = instrument_state(0, 0.08), probe = instrument_state(1, 0.09, 0.25);
  frame.instruments().push_back(probe);  // any order: by index
  frame.instruments().push_back(grasper);
  frame.instruments().push_back(instrument_state(3, 0.1));
  ASSERT_TRUE(publish(frame, 1, 40, liver.hash)) << testing::read_file(path("visual.log"));
  ASSERT_TRUE(wait_until([&] { return shown_in(1, 40) > 0; }, 60)) << testing::read_file(path("visual.log"));
  ASSERT_TRUE(frames_pass(5, 60));
  visual.signal(SIGINT);
  ASSERT_EQ(visual.wait(60), 0) << testing::read_file(path("visual.log"));

  // The last PNG that shows a frame: its row in frames.csv says both instruments were drawn.
  std::ifstream index(path("frames") + "/frames.csv");
  std::string line, header, last_png;
  std::getline(index, header);
  EXPECT_EQ(header, "png,seq,sim_time,contacts,max_displacement_m,instruments");
  int rows_with_two = 0;
  while (std::getline(index, line)) {
    const std::string instruments = line.substr(line.rfind(',') + 1);
    if (instruments == "2") {
      ++rows_with_two;
      last_png = line.substr(0, line.find(','));
    } else {
      EXPECT_EQ(instruments, "0") << "before the first frame no instrument, after it both: " << line;
    }
  }
  ASSERT_GT(rows_with_two, 0) << testing::read_file(path("frames") + "/frames.csv");
  const Image image = read_png(path("frames") + "/" + last_png);
  ASSERT_EQ(image.width, 320);

  // Across each shaft at 70, 80 and 90 % of the way from its trocar (out of the picture) to its tip (above the
  // organ): the pixels drawn, and how many are grey or blue.
  const auto across = [&](int i, const msg::InstrumentState& st, int& drawn, int& grey, int& blue) {
    Pose5 pose;
    pose.pitch = st.pose().pitch();
    pose.insertion = st.pose().insertion();
    const ToolGeometry g = tool_geometry(scene.tools[static_cast<std::size_t>(i)], pose);
    drawn = grey = blue = 0;
    for (const double f : {0.7, 0.8, 0.9}) {
      const Eigen::Vector3f at = (g.trocar + f * (g.tip - g.trocar)).cast<float>();
      const Eigen::Vector2f c = project_to_pixel(scene.visual.camera, image.width, image.height, at);
      const int y = static_cast<int>(c.y());
      for (int x = static_cast<int>(c.x()) - 6; x <= static_cast<int>(c.x()) + 6; ++x) {
        if (x < 0 || x >= image.width || y < 0 || y >= image.height) continue;
        const std::uint8_t* p = image.at(x, y);
        if (p[0] == kBackgroundRgb[0] && p[1] == kBackgroundRgb[1] && p[2] == kBackgroundRgb[2]) continue;
        ++drawn;
        grey += std::abs(p[0] - p[2]) < 40 ? 1 : 0;
        blue += p[2] > p[0] + 60 ? 1 : 0;
      }
    }
  };
  int drawn = 0, grey = 0, blue = 0;
  across(0, grasper, drawn, grey, blue);
  EXPECT_GT(drawn, 5) << "instrument 0 (grasper) in " << last_png;
  EXPECT_GE(grey, drawn - 2) << "instrument 0 is grey: " << grey << " of " << drawn << " in " << last_png;
  across(1, probe, drawn, grey, blue);
  EXPECT_GT(drawn, 5) << "instrument 1 (probe) in " << last_png;
  EXPECT_GE(blue, drawn - 2) << "instrument 1 is blue: " << blue << " of " << drawn << " in " << last_png;

  const auto v = json(path("visual.json"));
  EXPECT_TRUE(v.value("scene_confirmed", false));
  EXPECT_TRUE(v.value("instrument_count_ok", false));
  EXPECT_EQ(v.value("instruments", -1L), 2L);
  EXPECT_GE(v.value("instrument_states_ignored", -1L), 1L) << "the fourth instrument's states";
  EXPECT_EQ(v["deform_errors"].get<long>(), 0);
  const std::string log = testing::read_file(path("visual.log"));
  const auto at = log.find("carries a state for instrument 3");
  ASSERT_NE(at, std::string::npos) << log;
  EXPECT_NE(log.substr(at, log.find('\n', at) - at).find(scene_file), std::string::npos) << log;
  EXPECT_EQ(log.find("carries a state for instrument", at + 1), std::string::npos) << "said once\n" << log;
}

}  // namespace
}  // namespace surgsim
