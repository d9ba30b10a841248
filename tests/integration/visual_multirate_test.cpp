// The multirate liver in the real visual node: with liver.deformation multirate the node subscribes to
// BodyState and draws the tracker's shape it carries (one position per boundary surface node, SurfaceMesh order).
//  - RealNodeDrawsTheBodyStatesItIsSent: this test stands in for the haptic node over real Fast DDS (SceneInfo,
//    ContactFrames, BodyStates written with the generated types): the contact frame is drawn by the linear deformer
//    until the first body state; states of another scene, with one position too few and with a NaN are ignored,
//    counted by reason and named once each on stderr; a valid state is drawn: the VTK the node writes holds its
//    positions to float rounding.
//  - BothNodesDrawTheTrackersShape: the real haptic node (its tracker publishing BodyState) and the real visual node
//    on config/liver_multirate.yaml replaying the grasp-and-lift trajectory: the visual node drew body states and
//    ignored none, and the last VTK it wrote is the haptic node's last published shape to float rounding. Prints the
//    wire cost, the BodyState rate and the shape's age at draw.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/clock.h"
#include "dds_support.h"
#include "node_test.h"
#include "organ_view.h"
#include "process.h"
#include "support/contact_frame_util.h"
#include "surgsim_types.h"
#include "views/body_state_listener.h"
#include "views/liver_view.h"

using namespace surgsim::core;
using namespace surgsim::scene;

namespace surgsim {
namespace {

namespace fs = std::filesystem;
using eprosima::fastdds::dds::DataWriter;
using testing::Process;
using testing::wait_until;

// The points of a VTK surface the visual node wrote (empty when the file is missing or not complete yet).
std::vector<double> read_vtk_points(const std::string& file) {
  std::ifstream in(file);
  std::string line;
  while (std::getline(in, line) && line.rfind("POINTS ", 0) != 0) {
  }
  if (line.rfind("POINTS ", 0) != 0) return {};
  const long n = std::stol(line.substr(7));
  std::vector<double> xyz(3 * static_cast<std::size_t>(n));
  for (double& c : xyz) {
    if (!(in >> c)) return {};
  }
  std::string next;
  if (!(in >> next) || next != "CELLS") return {};  // the file is written while we read it
  return xyz;
}

// Cell `i` (from 0) of a frames.csv row: png, seq, sim_time, contacts, max_displacement_m, instruments.
std::string cell(const std::string& line, int i) {
  std::stringstream ss(line);
  std::string c;
  for (int k = 0; k <= i; ++k) std::getline(ss, c, ',');
  return c;
}

// The newest VTK file in `dir` (by name: frame_NNNNNN.vtk), or "".
std::string newest_vtk(const std::string& dir) {
  std::string best;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    if (e.path().extension() == ".vtk" && e.path().string() > best) best = e.path().string();
  }
  return best;
}

// Largest |a - b| over two point lists of the same size (infinity when the sizes differ).
double max_difference(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.size() != b.size() || a.empty()) return std::numeric_limits<double>::infinity();
  double d = 0;
  for (std::size_t i = 0; i < a.size(); ++i) d = std::max(d, std::abs(a[i] - b[i]));
  return d;
}

// Float rounding of coordinates of at most 0.2 m (2^-23 x 0.25), with the VTK's 9 significant digits.
constexpr double kFloatRounding = 3e-8;

class VisualMultirate : public testing::NodeTest {
 protected:
  void SetUp() override {
    prepare("visual_multirate", 41);
    // The shipped multirate liver with a small picture, every frame written with its VTK; the trajectory by
    // absolute path (the scene file moves to the test's folder).
    const std::string config = SURGSIM_TEST_CONFIG_DIR;
    std::string text = testing::read_file(config + "/liver_multirate.yaml");
    const auto set = [&](const std::string& from, const std::string& to) {
      const auto at = text.find(from);
      ASSERT_NE(at, std::string::npos) << from << " in liver_multirate.yaml";
      text.replace(at, from.size(), to);
    };
    set("width: 640", "width: 160");
    set("height: 480", "height: 120");
    set("png_every: 5", "png_every: 1");
    set("vtk: false", "vtk: true");
    set("trajectory: trajectories/", "trajectory: " + config + "/trajectories/");
    scene_file_ = path("liver_multirate.yaml");
    std::ofstream(scene_file_) << text;
    frames_ = path("frames");
  }
  void TearDown() override {
    participant_.reset();
    NodeTest::TearDown();
  }
  /// The test's participant on the nodes' private domain.
  dds::Participant& participant() {
    if (participant_ == nullptr) {
      dds::DdsOptions o;
      o.domain = domain_;
      o.profiles_file = std::string(SURGSIM_TEST_CONFIG_DIR) + "/dds/profiles.xml";
      o.name = "surgsim_test_multirate";
      participant_ = std::make_unique<dds::Participant>(o);
    }
    return *participant_;
  }
  std::string log(const std::string& name) const { return testing::read_file(path(name)); }

  std::string scene_file_;
  std::string frames_;
  std::unique_ptr<dds::Participant> participant_;
};

TEST_F(VisualMultirate, RealNodeDrawsTheBodyStatesItIsSent) {
  // The scene as the node loads it: its identity, tensors and boundary (rest positions, SurfaceMesh order).
  const Scene scene = load_scene(scene_file_);
  OrganViewOptions vo;
  vo.cache_dir = SURGSIM_TEST_CACHE_DIR;
  const LiverView view(scene, vo);
  ASSERT_TRUE(view.multirate());
  const Eigen::MatrixX3f& rest = view.deformer().rest();
  const int count = static_cast<int>(rest.rows());

  Process visual(bin("visual_node"), {"--scene", scene_file_, "--out", frames_, "--stats", path("visual.json")}, env_,
                 path("visual.log"));
  auto& p = participant();
  DataWriter* body_writer =
      p.writer(p.topic(dds::kBodyStateTopic, new msg::BodyStatePubSubType()), dds::kStreamWriter);
  DataWriter* frame_writer =
      p.writer(p.topic(dds::kContactFrameTopic, new msg::ContactFramePubSubType()), dds::kContactWriter);
  DataWriter* scene_writer = p.writer(p.topic(dds::kSceneInfoTopic, new msg::SceneInfoPubSubType()),
                                      dds::kLatchedWriter);
  // The node reads BodyState (a liver scene that is not multirate has no such reader).
  ASSERT_TRUE(wait_until(
      [&] {
        eprosima::fastdds::dds::PublicationMatchedStatus st;
        body_writer->get_publication_matched_status(st);
        return st.current_count > 0;
      },
      120))
      << "the visual node never subscribed to BodyState\n" << log("visual.log");
  msg::SceneInfo info;
  info.scene_name(scene.name);
  info.scene_hash(view.scene_hash());
  info.mesh_hash(view.mesh_hash());
  info.tensor_hash(view.tensor_hash());
  info.instrument_count(1);
  info.start_stamp_ns(monotonic_ns());
  scene_writer->write(&info);

  // 1. A contact frame and no body state yet: the linear deformer dents the organ (frames.csv: the contact drawn
  //    with a displacement).
  msg::ContactFrame frame = testing::press_frame(view.deformer().visible_nodes()[static_cast<std::size_t>(count / 2)],
                                                 -0.5);
  std::uint64_t seq = 0;
  const auto dented = [&] {
    std::ifstream index(frames_ + "/frames.csv");
    std::string line;
    while (std::getline(index, line)) {
      if (cell(line, 3) == "1" && std::strtod(cell(line, 4).c_str(), nullptr) > 1e-4) return true;
    }
    return false;
  };
  ASSERT_TRUE(wait_until(
      [&] {
        frame.seq(++seq);
        frame.stamp_ns(monotonic_ns());
        frame.scene_hash(view.scene_hash());
        frame_writer->write(&frame);
        return dented();
      },
      60))
      << "the linear deformer never drew the contact frame before the first body state\n" << log("visual.log");

  // 2. States the node must ignore (it takes the newest once a frame, at 50 Hz).
  msg::BodyState state;
  state.positions().resize(static_cast<std::size_t>(count));
  std::vector<double> good(3 * static_cast<std::size_t>(count));
  for (int v = 0; v < count; ++v) {
    // A lifted, sheared organ: 5 mm up, 2 % shear in x along z.
    const double x = rest(v, 0) + 0.02 * rest(v, 2), y = rest(v, 1), z = rest(v, 2) + 0.005;
    state.positions()[static_cast<std::size_t>(v)] = msg::Vec3();
    state.positions()[static_cast<std::size_t>(v)].x(x);
    state.positions()[static_cast<std::size_t>(v)].y(y);
    state.positions()[static_cast<std::size_t>(v)].z(z);
    good[3 * static_cast<std::size_t>(v)] = x;
    good[3 * static_cast<std::size_t>(v) + 1] = y;
    good[3 * static_cast<std::size_t>(v) + 2] = z;
  }
  std::uint64_t body_seq = 0;
  const auto send = [&](msg::BodyState& s, std::uint64_t hash) {
    s.seq(++body_seq);
    s.stamp_ns(monotonic_ns());
    s.scene_hash(hash);
    body_writer->write(&s);
  };
  // Each sent (100 Hz) until the node has named it on stderr.
  const auto refused = [&](msg::BodyState& s, std::uint64_t hash, const std::string& line) {
    return wait_until(
        [&] {
          send(s, hash);
          return log("visual.log").find(line) != std::string::npos;
        },
        60);
  };
  EXPECT_TRUE(refused(state, view.scene_hash() ^ 0x5a5a5a5aull, "ignored: scene hash")) << log("visual.log");
  msg::BodyState short_state = state;
  short_state.positions().pop_back();  // one position too few
  EXPECT_TRUE(refused(short_state, view.scene_hash(), "positions but the liver of scene")) << log("visual.log");
  msg::BodyState nan_state = state;
  nan_state.positions()[7].y(std::numeric_limits<double>::quiet_NaN());
  EXPECT_TRUE(refused(nan_state, view.scene_hash(), "a position is not finite")) << log("visual.log");

  // 3. The valid state, until a VTK the node wrote holds it. The node carries the state to each frame's contacts (their
  //    u_tilde, the imposed displacement in this mode): the frame's contact node is imposed where the state has it.
  const int pressed = count / 2;
  frame.contacts()[0].u_tilde().x(good[3 * static_cast<std::size_t>(pressed)] - rest(pressed, 0));
  frame.contacts()[0].u_tilde().y(good[3 * static_cast<std::size_t>(pressed) + 1] - rest(pressed, 1));
  frame.contacts()[0].u_tilde().z(good[3 * static_cast<std::size_t>(pressed) + 2] - rest(pressed, 2));
  double error = std::numeric_limits<double>::infinity();
  const bool drawn = wait_until(
      [&] {
        frame.seq(++seq);
        frame.stamp_ns(monotonic_ns());
        frame_writer->write(&frame);
        send(state, view.scene_hash());
        const std::string vtk = newest_vtk(frames_);
        if (!vtk.empty()) error = max_difference(read_vtk_points(vtk), good);
        return error <= kFloatRounding;
      },
      60);
  visual.signal(SIGINT);
  ASSERT_EQ(visual.wait(60), 0) << log("visual.log");
  EXPECT_TRUE(drawn) << "no VTK holds the body state sent (last difference " << error << " m)\n" << log("visual.log");

  const auto v = json(path("visual.json"));
  ASSERT_TRUE(v.contains("multirate")) << v.dump();
  const nlohmann::json& m = v["multirate"];
  EXPECT_EQ(m["surface_nodes"].get<int>(), count);
  EXPECT_GE(m["body_states_shown"].get<long>(), 1) << m.dump();
  EXPECT_GE(m["frames_linear_fallback"].get<long>(), 1) << m.dump();
  EXPECT_GE(m["frames_body_state"].get<long>(), 1) << m.dump();
  EXPECT_GE(m["body_states_rejected"]["wrong_scene"].get<long>(), 1) << m.dump();
  EXPECT_GE(m["body_states_rejected"]["wrong_count"].get<long>(), 1) << m.dump();
  EXPECT_GE(m["body_states_rejected"]["non_finite"].get<long>(), 1) << m.dump();
  EXPECT_GE(m["shape_age_ms"]["count"].get<long>(), 1) << m.dump();
  // One stderr line per reason, naming what was expected.
  const std::string err = log("visual.log");
  for (const std::string& what :
       {"scene hash " + std::to_string(view.scene_hash() ^ 0x5a5a5a5aull) + " but this node's scene",
        std::to_string(count - 1) + " positions but the liver of scene", std::string("a position is not finite")}) {
    const auto at = err.find(what);
    ASSERT_NE(at, std::string::npos) << what << "\n" << err;
    EXPECT_EQ(err.find(what, at + 1), std::string::npos) << "said once: " << what << "\n" << err;
  }
  EXPECT_NE(err.find("has " + std::to_string(count) + " boundary surface nodes"), std::string::npos) << err;
  EXPECT_NE(err.find("has hash " + std::to_string(view.scene_hash())), std::string::npos) << err;
}

TEST_F(VisualMultirate, BothNodesDrawTheTrackersShape) {
  OrganViewOptions vo;
  vo.cache_dir = SURGSIM_TEST_CACHE_DIR;
  const LiverView view(load_scene(scene_file_), vo);  // the rest boundary, SurfaceMesh order
  const Eigen::MatrixX3f& rest = view.deformer().rest();
  const auto displacement = [&](const std::vector<double>& xyz, int count) {
    double d = 0;
    for (int k = 0; k < count && k < rest.rows(); ++k) {
      const Eigen::Vector3d p(xyz[3 * static_cast<std::size_t>(k)], xyz[3 * static_cast<std::size_t>(k) + 1],
                              xyz[3 * static_cast<std::size_t>(k) + 2]);
      d = std::max(d, (p - rest.row(k).transpose().cast<double>()).norm());
    }
    return d;
  };
  // The test reads the BodyStates too (every 2 ms while the haptic node runs): the largest displacement published,
  // and the newest state, which at the end is the haptic node's last.
  std::unique_ptr<BodyStateListener> states = subscribe_body_states(participant());
  std::vector<double> last(3 * static_cast<std::size_t>(msg::kMaxBodyPoints)), newest = last;
  int last_count = -1;
  BodyStateHeader last_header;
  double published_max = 0;
  std::atomic<bool> running{true};
  std::thread reader([&] {
    InstrumentPoses instruments;
    BodyStateHeader header;
    std::uint64_t received = 0;
    while (running.load()) {
      const int count = states->take(newest.data(), 1, instruments, header, received);
      if (count > 0) {
        published_max = std::max(published_max, displacement(newest, count));
        std::swap(last, newest);
        last_count = count;
        last_header = header;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  });
  Process visual(bin("visual_node"), {"--scene", scene_file_, "--out", frames_, "--stats", path("visual.json")}, env_,
                 path("visual.log"));
  Process haptic(bin("haptic_node"),
                 {"--scene", scene_file_, "--replay", std::string(SURGSIM_TEST_CONFIG_DIR) +
                  "/trajectories/liver_grasp_lift.csv", "--wait-for-visual", "120", "--rt-priority", "0",
                  "--stats", path("haptic.json")},
                 env_, path("haptic.log"));
  const int haptic_exit = haptic.wait(300);
  std::this_thread::sleep_for(std::chrono::milliseconds(600));  // the visual node draws the last state
  running.store(false);
  reader.join();
  ASSERT_EQ(haptic_exit, 0) << log("haptic.log");
  visual.signal(SIGINT);
  ASSERT_EQ(visual.wait(60), 0) << log("visual.log");

  const auto h = json(path("haptic.json"));
  const auto v = json(path("visual.json"));
  ASSERT_TRUE(h.contains("multirate")) << h.dump();
  ASSERT_TRUE(v.contains("multirate")) << v.dump();
  const nlohmann::json& hm = h["multirate"];
  const nlohmann::json& vm = v["multirate"];
  const long published = hm["body_states_published"].get<long>();
  EXPECT_GT(published, 0) << hm.dump();
  EXPECT_GT(vm["body_states_shown"].get<long>(), 0) << vm.dump();
  EXPECT_EQ(vm["body_states_rejected"]["total"].get<long>(), 0) << vm.dump() << "\n" << log("visual.log");
  EXPECT_EQ(vm["last_seq_shown"].get<long>(), published) << "the last state drawn is the last published";
  EXPECT_EQ(vm["last_state_instruments"].get<int>(), 1) << "a BodyState carries every instrument's state";

  // The last VTK the node wrote against the last BodyState published (as this test received it).
  ASSERT_GT(last_count, 0) << "the test received no BodyState";
  EXPECT_EQ(last_count, vm["surface_nodes"].get<int>());
  EXPECT_EQ(static_cast<long>(last_header.seq), published);
  last.resize(3 * static_cast<std::size_t>(last_count));
  const std::string vtk = newest_vtk(frames_);
  ASSERT_FALSE(vtk.empty());
  EXPECT_LE(max_difference(read_vtk_points(vtk), last), kFloatRounding) << vtk << " against BodyState "
                                                                         << last_header.seq;

  // The lifted lobe was published and drawn: the largest displacement in frames.csv (every frame) is the largest
  // published (the lift holds for a while, so the frames see it).
  std::ifstream index(frames_ + "/frames.csv");
  std::string line;
  double drawn_max = 0;
  std::getline(index, line);
  while (std::getline(index, line)) drawn_max = std::max(drawn_max, std::strtod(cell(line, 4).c_str(), nullptr));
  EXPECT_GT(published_max, 0.005) << "the tracker's shape of the lifted lobe";
  EXPECT_NEAR(drawn_max, published_max, 0.05 * published_max);

  // Figures (README): the wire cost of one BodyState, the rate it came at, the shape's age when drawn.
  msg::BodyStatePubSubType type;
  msg::BodyState sample;
  sample.positions().resize(static_cast<std::size_t>(last_count));
  sample.instruments().resize(1);
  const double wall = h.value("wall_seconds", 0.0);
  std::printf("multirate liver live: %d surface nodes, BodyState %u bytes serialized, %ld published in %.2f s "
              "(%.1f /s), %ld shown, shape age at draw p50 %.2f ms p99 %.2f ms (%ld frames), at its first draw p50 %.2f ms "
              "p99 %.2f ms, largest displacement "
              "published %.4f m, drawn %.4f m\n",
              last_count, static_cast<unsigned>(type.getSerializedSizeProvider(&sample)()), published, wall,
              wall > 0 ? static_cast<double>(published) / wall : 0.0, vm["body_states_shown"].get<long>(),
              vm["shape_age_ms"]["p50"].get<double>(), vm["shape_age_ms"]["p99"].get<double>(),
              vm["shape_age_ms"]["count"].get<long>(), vm["shape_age_first_draw_ms"]["p50"].get<double>(),
              vm["shape_age_first_draw_ms"]["p99"].get<double>(), published_max, drawn_max);
}

}  // namespace
}  // namespace surgsim
