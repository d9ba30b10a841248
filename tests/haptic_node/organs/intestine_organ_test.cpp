// The intestine organ with several instruments: one probe per instrument at its tool tip, each with its own
// force (clamped to its own device limit) and contact count; a lost instrument has no probe and zero force, the
// others go on as if it were not there; the step allocates nothing; BodyState carries every instrument's state.
#include "organs/intestine_organ.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

#include "publisher.h"
#include "support/alloc_counter.h"
#include "support/test_domain.h"

using namespace surgsim::tool;
using namespace surgsim::contact;
using namespace surgsim::scene;

namespace surgsim {
namespace {

using eprosima::fastdds::dds::DataReader;
using eprosima::fastdds::dds::DataReaderListener;
using eprosima::fastdds::dds::SampleInfo;
using eprosima::fastrtps::types::ReturnCode_t;

// The shipped intestine scene with two instruments: "left" (the scene's tool) and "right", with these device limits;
// without gravity, so that the body stays where the probes press it.
Scene two_tool_scene(double left_limit, double right_limit) {
  setenv("SURGSIM_CONFIG_DIR", SURGSIM_TEST_CONFIG_DIR, 1);
  Scene scene = load_scene(resolve_scene_path("intestine"));
  scene.intestine.params.gravity.setZero();
  ToolSpec left = scene.tools.at(0), right = scene.tools.at(0);
  left.name = "left";
  left.force_limit = left_limit;
  right.name = "right";
  right.force_limit = right_limit;
  scene.tools = {left, right};
  return scene;
}

// A tool whose tip is `depth` (m) inside the intestine's rest surface at the middle of segment `segment`, from
// outside the cylinder (the organ's probe radius); `out` is the radial direction there, away from the vessel.
ToolGeometry pressing(const IntestineOrgan& organ, const Scene& scene, int segment, double depth,
                      Eigen::Vector3d& out) {
  const intestine::IntestineModel& model = organ.model();
  const intestine::IntestineParams& p = model.params();
  const Eigen::Vector3d mid = 0.5 * (model.rest().col(segment) + model.rest().col(segment + 1));
  const Eigen::Vector3d axis = p.axis_direction.normalized();
  out = mid - p.axis_origin;
  out = (out - out.dot(axis) * axis).normalized();
  ToolGeometry g{};
  g.tip = mid + out * (p.intestine_radius + scene.intestine.probe_radius - depth);
  return g;
}

bool same_state(const IntestineOrgan& a, const IntestineOrgan& b) {
  const auto bytes = sizeof(double) * static_cast<std::size_t>(a.state().x.size());
  return std::memcmp(a.state().x.data(), b.state().x.data(), bytes) == 0 &&
         std::memcmp(a.state().v.data(), b.state().v.data(), bytes) == 0;
}

// Two instruments pressing at two places get each the force of its own probe: what the same press gives alone
// (1e-12, the contacts are found at the positions on entry), pointing out of the body; the contact counts add up.
TEST(IntestineOrganTest, TwoInstrumentsEachGetTheirOwnProbeForce) {
  const Scene scene = two_tool_scene(8.0, 8.0);
  IntestineOrgan both(scene, 100), left_alone(scene, 100), right_alone(scene, 100);
  Eigen::Vector3d out_l, out_r;
  const ToolGeometry gl = pressing(both, scene, 20, 0.012, out_l);
  const ToolGeometry gr = pressing(both, scene, 70, 0.006, out_r);
  const InstrumentInput in[2] = {{&gl, 0.0}, {&gr, 0.0}};
  ContactTick t[2], tl, tr[2];
  both.step(in, 2, 1e-3, t);
  left_alone.step(&gl, 0.0, 1e-3, tl);
  const InstrumentInput right_only[2] = {{nullptr, 0.0}, {&gr, 0.0}};
  right_alone.step(right_only, 2, 1e-3, tr);

  ASSERT_GT(t[0].points_in_contact, 0);
  ASSERT_GT(t[1].points_in_contact, 0);
  EXPECT_LE((t[0].device_force - tl.device_force).norm(), 1e-12);
  EXPECT_LE((t[1].device_force - tr[1].device_force).norm(), 1e-12);
  EXPECT_GT(t[0].device_force.dot(out_l), 0.9 * t[0].device_force.norm());
  EXPECT_GT(t[1].device_force.dot(out_r), 0.9 * t[1].device_force.norm());
  EXPECT_GT(t[0].device_force.norm(), 1.5 * t[1].device_force.norm());  // twice as deep: not one shared force
  EXPECT_EQ(t[0].force, t[0].device_force);                             // under the limit: no clamp
  EXPECT_FALSE(t[0].saturated || t[1].saturated || t[0].nonfinite || t[1].nonfinite);
  EXPECT_EQ(both.instrument_contacts(0), t[0].points_in_contact);
  EXPECT_EQ(both.instrument_contacts(1), t[1].points_in_contact);
  EXPECT_EQ(both.contacts(), t[0].points_in_contact + t[1].points_in_contact);
  EXPECT_EQ(both.instrument_contacts(2), 0);
  EXPECT_EQ(both.instrument_contacts(-1), 0);
  EXPECT_EQ(right_alone.instrument_contacts(0), 0);
  EXPECT_EQ(tr[0].device_force, Eigen::Vector3d::Zero());
}

// Instrument 1 presses, then its input is lost (tool null) while instrument 0 keeps pressing: from then on the organ
// is exactly (bit for bit) one stepped with instrument 0 alone, and instrument 1 gets zero force and no contact;
// while both press the two organs are the same too, and the lost probe is not held at its last tip.
TEST(IntestineOrganTest, ALostInstrumentHasNoProbeAndTheOtherGoesOn) {
  const Scene scene = two_tool_scene(8.0, 8.0);
  IntestineOrgan lost(scene, 400), one_after(scene, 400);
  Eigen::Vector3d out;
  const ToolGeometry g0 = pressing(lost, scene, 20, 0.01, out);
  const ToolGeometry g1 = pressing(lost, scene, 70, 0.01, out);
  const InstrumentInput both[2] = {{&g0, 0.0}, {&g1, 0.0}};
  const InstrumentInput second_lost[2] = {{&g0, 0.0}, {nullptr, 0.0}};
  int right_contacts = 0, left_ticks_after = 0;
  for (int k = 0; k < 300; ++k) {
    ContactTick a[2], b[2];
    if (k < 100) {
      lost.step(both, 2, 1e-3, a);
      one_after.step(both, 2, 1e-3, b);
      right_contacts += a[1].points_in_contact;
      continue;
    }
    lost.step(second_lost, 2, 1e-3, a);
    one_after.step(&g0, 0.0, 1e-3, b[0]);
    ASSERT_EQ(a[0].device_force, b[0].device_force) << "tick " << k;
    ASSERT_EQ(a[0].points_in_contact, b[0].points_in_contact) << "tick " << k;
    ASSERT_EQ(a[1].device_force, Eigen::Vector3d::Zero()) << "tick " << k;
    ASSERT_EQ(a[1].force, Eigen::Vector3d::Zero()) << "tick " << k;
    ASSERT_EQ(a[1].points_in_contact, 0) << "tick " << k;
    ASSERT_FALSE(a[1].nonfinite || a[1].saturated || a[1].over_capacity) << "tick " << k;
    ASSERT_EQ(lost.instrument_contacts(1), 0) << "tick " << k;
    ASSERT_EQ(lost.contacts(), a[0].points_in_contact) << "tick " << k;
    left_ticks_after += a[0].points_in_contact > 0;
  }
  EXPECT_GT(right_contacts, 0);      // instrument 1 did press before its input was lost
  EXPECT_GT(left_ticks_after, 100);  // and instrument 0 after it
  EXPECT_TRUE(same_state(lost, one_after));
}

// Deep presses: each instrument's device force is its own device limit, the force before the clamp exceeds it.
TEST(IntestineOrganTest, EachInstrumentIsClampedToItsOwnDeviceLimit) {
  const Scene scene = two_tool_scene(2.0, 5.0);
  IntestineOrgan organ(scene, 100);
  Eigen::Vector3d out;
  const double deep = organ.model().params().intestine_radius + scene.intestine.probe_radius - 0.002;
  const ToolGeometry g0 = pressing(organ, scene, 20, deep, out);
  const ToolGeometry g1 = pressing(organ, scene, 70, deep, out);
  const InstrumentInput in[2] = {{&g0, 0.0}, {&g1, 0.0}};
  ContactTick t[2];
  organ.step(in, 2, 1e-3, t);
  const double limits[2] = {2.0, 5.0};
  for (int i = 0; i < 2; ++i) {
    EXPECT_TRUE(t[i].saturated) << "instrument " << i;
    EXPECT_NEAR(t[i].device_force.norm(), limits[i], 1e-9) << "instrument " << i;
    EXPECT_GT(t[i].force.norm(), limits[i]) << "instrument " << i;
    EXPECT_NEAR(t[i].force.normalized().dot(t[i].device_force.normalized()), 1.0, 1e-12) << "instrument " << i;
  }
  const nlohmann::json stats = organ.stats();
  ASSERT_EQ(stats["probes"].size(), 2u);
  EXPECT_EQ(stats["probes"][0]["name"], "left");
  EXPECT_EQ(stats["probes"][1]["name"], "right");
  EXPECT_EQ(stats["probes"][1]["saturated_ticks"].get<int>(), 1);
  EXPECT_NEAR(stats["probes"][0]["force_max_n"].get<double>(), 2.0, 1e-9);
  EXPECT_NEAR(stats["probes"][1]["force_max_n"].get<double>(), 5.0, 1e-9);
  EXPECT_EQ(stats["probes"][0]["contacts_max"].get<int>(), t[0].points_in_contact);
  EXPECT_EQ(stats["probe_contacts_max"].get<int>(), t[0].points_in_contact + t[1].points_in_contact);
  EXPECT_EQ(stats["saturated_ticks"].get<int>(), 1);
}

// Two instruments moving through the folds: the step allocates nothing.
TEST(IntestineOrganTest, StepWithTwoInstrumentsAllocatesNothing) {
  const Scene scene = two_tool_scene(8.0, 8.0);
  IntestineOrgan organ(scene, 2000);
  Eigen::Vector3d out[2];
  ToolGeometry g[2] = {pressing(organ, scene, 20, 0.01, out[0]), pressing(organ, scene, 70, 0.01, out[1])};
  const InstrumentInput in[2] = {{&g[0], 0.0}, {&g[1], 0.0}};
  ContactTick t[2];
  for (int k = 0; k < 200; ++k) organ.step(in, 2, 1e-3, t);
  test::AllocationCounter counter;
  int touching[2] = {0, 0};
  for (int k = 0; k < 800; ++k) {
    // Sweep each probe inwards, towards the vessel, through the folds (whatever the rest shape's orientation there).
    g[0].tip -= 5e-5 * out[0];
    g[1].tip -= 5e-5 * out[1];
    organ.step(in, 2, 1e-3, t);
    for (int i = 0; i < 2; ++i) touching[i] += t[i].points_in_contact > 0;
  }
  EXPECT_EQ(counter.count(), 0);
  EXPECT_GT(touching[0], 0);
  EXPECT_GT(touching[1], 0);
  EXPECT_EQ(organ.faults(), 0u);
}

// What the test's reader receives of BodyState (a DDS listener thread).
class BodyReader : public DataReaderListener {
 public:
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    std::lock_guard<std::mutex> lock(mutex);
    while (reader->take_next_sample(&sample_, &info) == ReturnCode_t::RETCODE_OK) {
      if (info.valid_data) received.push_back(sample_);
    }
  }
  std::mutex mutex;
  std::vector<msg::BodyState> received;

 private:
  msg::BodyState sample_;
};

// write(): the BodyState of a tick carries every instrument (index, pose, tip, direction, force, contact points,
// flags) and the body's positions, keyed by the organ index the factory gave the organ (here organ 3 of a scene).
TEST(IntestineOrganTest, BodyStateCarriesEveryInstrument) {
  const Scene scene = two_tool_scene(8.0, 8.0);
  IntestineOrgan organ(scene, 100);
  dds::DdsOptions o;
  o.domain = test::reserve_test_domain();
  o.profiles_file = std::string(SURGSIM_TEST_CONFIG_DIR) + "/dds/profiles.xml";
  o.name = "surgsim_intestine_organ_test";
  dds::Participant participant(o);
  BodyReader seen;
  DataReader* reader = participant.reader(participant.topic(dds::kBodyStateTopic, new msg::BodyStatePubSubType()),
                                          dds::kStreamReader, &seen);
  organ.set_organ_index(3);  // as CompositeOrgan does for each part, before the writers
  organ.create_writers(participant, 0x1234);

  Eigen::Vector3d out;
  const ToolGeometry g0 = pressing(organ, scene, 20, 0.01, out);
  const ToolGeometry g1 = pressing(organ, scene, 70, 0.005, out);
  const InstrumentInput in[2] = {{&g0, 0.0}, {&g1, 0.0}};
  ContactTick t[2];
  organ.step(in, 2, 1e-3, t);
  std::vector<double> points(3 * static_cast<std::size_t>(organ.output_points()));
  TickRecord r;
  r.seq = 42;
  r.sim_time = 0.042;
  r.instrument_count = 2;
  r.organ.point_capacity = organ.output_points();
  r.organ.points = points.data();
  organ.fill_outputs(r.organ);
  for (int i = 0; i < 2; ++i) {
    InstrumentRecord& ir = r.instruments[static_cast<std::size_t>(i)];
    ir.pose.pitch = 0.1 * (i + 1);
    ir.pose.insertion = 0.2 + i;
    ir.tip = i == 0 ? g0.tip : g1.tip;
    ir.force = t[i].force;
    ir.direction = Eigen::Vector3d(0, 0, i == 0 ? 1 : -1);
    ir.flags = i == 0 ? 0u : 8u;
    ir.contact_points = static_cast<std::uint32_t>(t[i].points_in_contact);
  }

  eprosima::fastdds::dds::SubscriptionMatchedStatus matched;
  for (int w = 0; w < 500 && (reader->get_subscription_matched_status(matched), matched.current_count == 0); ++w) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_GT(matched.current_count, 0) << "the BodyState writer and the test's reader never matched";
  bool got = false;
  for (int w = 0; w < 100 && !got; ++w) {
    organ.write(r, 777);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    std::lock_guard<std::mutex> lock(seen.mutex);
    got = !seen.received.empty();
  }
  ASSERT_TRUE(got) << "no BodyState received";
  std::lock_guard<std::mutex> lock(seen.mutex);
  const msg::BodyState& b = seen.received.front();
  EXPECT_EQ(b.organ(), 3u) << "BodyState's key is the organ's index";
  EXPECT_EQ(b.seq(), 42u);
  EXPECT_EQ(b.scene_hash(), 0x1234u);
  ASSERT_EQ(b.instruments().size(), 2u);
  for (int i = 0; i < 2; ++i) {
    const msg::InstrumentState& s = b.instruments()[static_cast<std::size_t>(i)];
    const InstrumentRecord& ir = r.instruments[static_cast<std::size_t>(i)];
    EXPECT_EQ(s.instrument(), static_cast<std::uint32_t>(i));
    EXPECT_EQ(s.pose().pitch(), ir.pose.pitch);
    EXPECT_EQ(s.pose().insertion(), ir.pose.insertion);
    EXPECT_EQ(Eigen::Vector3d(s.tip().x(), s.tip().y(), s.tip().z()), ir.tip.eigen());
    EXPECT_EQ(Eigen::Vector3d(s.force().x(), s.force().y(), s.force().z()), ir.force.eigen());
    EXPECT_EQ(s.direction().z(), ir.direction.v[2]);
    EXPECT_EQ(s.contact_points(), ir.contact_points);
    EXPECT_EQ(s.flags(), ir.flags);
  }
  EXPECT_GT(b.instruments()[0].contact_points(), 0u);
  ASSERT_EQ(b.positions().size(), static_cast<std::size_t>(organ.output_points()));
  EXPECT_EQ(b.positions()[7].z(), organ.state().x(2, 7));
  EXPECT_EQ(organ.stats()["body_states_published"].get<int>() > 0, true);
}

}  // namespace
}  // namespace surgsim
