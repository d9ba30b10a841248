// The multirate liver in the haptic node (liver.deformation: multirate; nonlinear/multirate_contacts.h) on the
// shipped scene config/liver_multirate.yaml (the 1.4k liver, tensors from the cache), with the tool moved over the
// thick part of the liver (liver.yaml's trocar) and a device limit out of the way. The tracker runs without its
// thread: the test cycles it with cycle_once() between ticks, so every figure is deterministic.
//   - a held deep press: before any snapshot the force is the linear model's; once the tracker converged it is the
//     snapshot's reaction sum (Newton's) and differs from the linear force by more than the linear model's error at
//     that depth;
//   - a slide under the press changes the patch's node set: those ticks take the partial match, stay finite and
//     change the force by no more than the linear model's own largest step on the same slide plus 5 % of the force;
//   - the tick allocates nothing; the tracker sleeps when nothing changes.
// Figures are printed: ctest -R haptic_liver_multirate -V.
#include "nonlinear/multirate_contacts.h"

#include <dlfcn.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>

#include "core/error.h"
#include "mesh/box_mesh.h"
#include "organs/liver_organ.h"
#include "support/alloc_counter.h"
#include "support/slab_util.h"
#include "tool/trajectory.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::tool;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::contact;
using namespace surgsim::intestine;
using namespace surgsim::scene;

namespace surgsim {
namespace {

constexpr double kDt = 1e-3;

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}
constexpr double kTopZ = 0.042;  // m, the rest surface under liver.yaml's trocar (x 0.03, y 0)

Scene test_scene(LiverDeformation d) {
  Scene s = load_scene(resolve_scene_path("liver_multirate"));
  s.liver.deformation = d;
  s.tools[0].force_limit = 1000;  // N: the clamp never acts here
  return s;
}

Scene with_model(Scene s, ContactModel model) {
  s.tools[0].contact_model = model;
  return s;
}

struct Pair {
  explicit Pair(ContactModel model = ContactModel::kPatch)
      : mr_scene(with_model(test_scene(LiverDeformation::kMultirate), model)),
        lin_scene(with_model(test_scene(LiverDeformation::kLinear), model)) {
    m.set_prediction(true, 0.030);  // deterministic: the horizon of a 30-tick cycle, not a measured one
  }
  Scene mr_scene;
  Scene lin_scene;
  LiverOrgan mr{mr_scene, SURGSIM_TEST_CACHE_DIR, nullptr, false};
  LiverOrgan lin{lin_scene, SURGSIM_TEST_CACHE_DIR, nullptr, false};
  MultirateContacts& m = *mr.multirate();

  // One tick of both organs with a vertical tool whose tip is at `tip` (jaw open).
  void step(const Eigen::Vector3d& tip, ContactTick& t_mr, ContactTick& t_lin) {
    const ToolGeometry g = test::vertical_tool(tip);
    mr.step(&g, 0.5, kDt, t_mr);
    lin.step(&g, 0.5, kDt, t_lin);
  }
};

Eigen::Vector3d snapshot_force(const TrackerSnapshot& s) {
  Eigen::Vector3d f = Eigen::Vector3d::Zero();
  for (int k = 0; k < s.count; ++k) f -= s.reaction[static_cast<std::size_t>(k)];
  return f;
}

// Down from 3 mm above the top at 0.1 m/s to `depth` below it, both organs, the tracker never cycled.
void press(Pair& p, double depth, ContactTick& t_mr, ContactTick& t_lin, double* worst_diff = nullptr) {
  const int ticks = static_cast<int>(std::lround((depth + 0.003) / 0.1 / kDt));
  for (int k = 0; k <= ticks; ++k) {
    const Eigen::Vector3d tip(0.03, 0.0, kTopZ + 0.003 - (depth + 0.003) * k / ticks);
    p.step(tip, t_mr, t_lin);
    if (worst_diff != nullptr && t_lin.force.norm() > 0)
      *worst_diff = std::max(*worst_diff, (t_mr.force - t_lin.force).norm() / t_lin.force.norm());
  }
}

// Ticks at `tip` with a tracker cycle between them until the tracker goes idle (converged at unchanged targets).
int hold_until_converged(Pair& p, const Eigen::Vector3d& tip, ContactTick& t_mr, ContactTick& t_lin) {
  for (int c = 1; c <= 120; ++c) {
    p.step(tip, t_mr, t_lin);
    if (!p.m.cycle_once()) {
      p.step(tip, t_mr, t_lin);
      return c;
    }
  }
  return -1;
}

TEST(MultirateContactsNode, HeldDeepPressIsLinearBeforeASnapshotThenNewtons) {
  Pair p;
  // 17 mm: 20 % of the liver's 85 mm height, where the linear model's force error against Newton is 10 % on the flat
  // punch (README, large deformation table).
  const double depth = 0.017;
  ContactTick t_mr, t_lin;
  double before = 0;
  press(p, depth, t_mr, t_lin, &before);
  ASSERT_GT(t_lin.force.norm(), 0.1);
  EXPECT_LE(before, 1e-12) << "before any snapshot the force is the linear model's";
  EXPECT_EQ(p.m.ticks_nonlinear() + p.m.ticks_partial(), 0u);

  const Eigen::Vector3d tip(0.03, 0.0, kTopZ - depth);
  const int cycles = hold_until_converged(p, tip, t_mr, t_lin);
  ASSERT_GT(cycles, 0) << "the tracker did not converge on the held press";
  const TrackerSnapshot& s = p.m.snapshot();
  ASSERT_TRUE(s.valid && s.converged);
  const Eigen::Vector3d f_snap = snapshot_force(s);
  const double to_snapshot = (t_mr.force - f_snap).norm() / f_snap.norm();
  const double to_linear = (t_mr.force - t_lin.force).norm() / t_lin.force.norm();
  std::cout << "[press] " << depth * 1e3 << " mm held, " << p.mr.contacts() << " contact nodes: linear "
            << t_lin.force.transpose() << " N; multirate after " << cycles << " tracker cycles "
            << t_mr.force.transpose() << " N (snapshot reaction sum " << f_snap.transpose()
            << " N, relative difference " << to_snapshot << "); multirate against linear " << 100 * to_linear << " %\n";
  EXPECT_LT(to_snapshot, 1e-9) << "the held press feels the converged snapshot's reactions";
  // The tip's near field (contact/near_field.h) is linear and in series: the tracker bends the mesh's part only, so
  // the difference is a smaller share of the force than with the mesh-sized patch of before (over 10 % then).
  EXPECT_GT(to_linear, 0.05) << "the non-linear force differs from the linear one";
  EXPECT_GT(p.m.ticks_nonlinear(), 0u);
  EXPECT_TRUE(t_mr.device_force.allFinite());
}

// The ContactFrame's u_tilde of a multirate liver is each contact node's imposed displacement this tick (the
// tracker's target, which the visual node carries the tracker's last shape to); a linear liver keeps the paper's
// corrected constraint G_kk lambda_k.
TEST(MultirateContactsNode, ContactEntriesCarryTheImposedDisplacement) {
  Pair p;
  ContactTick t_mr, t_lin;
  press(p, 0.008, t_mr, t_lin);
  hold_until_converged(p, Eigen::Vector3d(0.03, 0.0, kTopZ - 0.008), t_mr, t_lin);
  const ContactSolution& s = p.mr.liver_contacts().solution();
  ASSERT_GT(s.count, 0);
  ASSERT_EQ(p.mr.contact_entries(), s.count);
  double deepest = 0;
  for (int l = 0; l < s.count; ++l) {
    const ContactEntry e = p.mr.contact_entry(l);
    EXPECT_EQ(e.node, s.nodes[static_cast<std::size_t>(l)]);
    EXPECT_EQ(e.u_tilde, s.displacement[static_cast<std::size_t>(l)]) << "entry " << l;
    deepest = std::min(deepest, e.u_tilde.z());
  }
  EXPECT_LT(deepest, -0.004) << "the patch's nodes are pressed down by about the tool's 8 mm";
  const ContactEntry lin = p.lin.contact_entry(0);
  EXPECT_EQ(lin.u_tilde, p.lin.liver_contacts().corrected(0));
}

// The largest |u_now - u_snapshot| over the solution's nodes the snapshot holds (m): how far the local model is
// evaluated from its expansion point.
double extrapolation(const LiverOrgan& organ, const TrackerSnapshot& s) {
  const ContactSolution& sol = organ.liver_contacts().solution();
  double out = 0;
  for (int l = 0; l < sol.count; ++l)
    for (int j = 0; j < s.count; ++j)
      if (s.nodes[static_cast<std::size_t>(j)] == sol.nodes[static_cast<std::size_t>(l)])
        out = std::max(out, (sol.displacement[static_cast<std::size_t>(l)] - s.u[static_cast<std::size_t>(j)]).norm());
  return out;
}

struct Slide {
  std::uint64_t partial = 0;
  double step_mr = 0, step_lin = 0, force_min = HUGE_VAL;  // N
  bool finite = true;
  long allocations = 0;
  double extrapolation_mean = 0, extrapolation_max = 0;  // m
};

// Pressed 10 mm and converged, then 2 cm along x at 0.05 m/s (the patch's edge nodes enter and leave) with a tracker
// cycle every 30 ticks (about the node's cycle time on this liver), its targets predicted 30 ms ahead or not.
Slide slide(bool predict) {
  Pair p;
  p.m.set_prediction(predict, 0.030);
  Slide r;
  const double depth = 0.010;
  ContactTick t_mr, t_lin;
  press(p, depth, t_mr, t_lin);
  EXPECT_GT(hold_until_converged(p, Eigen::Vector3d(0.03, 0.0, kTopZ - depth), t_mr, t_lin), 0);
  const std::uint64_t partial0 = p.m.ticks_partial();
  Eigen::Vector3d prev_mr = t_mr.force, prev_lin = t_lin.force;
  const int ticks = 400;
  for (int k = 1; k <= ticks; ++k) {
    const Eigen::Vector3d tip(0.03 + 0.02 * k / ticks, 0.0, kTopZ - depth);
    const ToolGeometry g = test::vertical_tool(tip);
    {
      test::AllocationCounter counter;
      p.mr.step(&g, 0.5, kDt, t_mr);
      r.allocations += counter.count();
    }
    p.lin.step(&g, 0.5, kDt, t_lin);
    r.finite = r.finite && t_mr.device_force.allFinite() && !t_mr.nonfinite;
    r.step_mr = std::max(r.step_mr, (t_mr.force - prev_mr).norm());
    r.step_lin = std::max(r.step_lin, (t_lin.force - prev_lin).norm());
    r.force_min = std::min(r.force_min, t_mr.force.norm());
    const double e = extrapolation(p.mr, p.m.snapshot());
    r.extrapolation_mean += e / ticks;
    r.extrapolation_max = std::max(r.extrapolation_max, e);
    prev_mr = t_mr.force;
    prev_lin = t_lin.force;
    if (k % 30 == 0) p.m.cycle_once();
  }
  r.partial = p.m.ticks_partial() - partial0;
  return r;
}

// The paper's triangle contact model takes the same path: its solution's nodes and displacements are the targets.
TEST(MultirateContactsNode, TriangleModelHeldPressFeelsTheConvergedSnapshot) {
  Pair p(ContactModel::kTriangle);
  const double depth = 0.010;
  ContactTick t_mr, t_lin;
  double before = 0;
  press(p, depth, t_mr, t_lin, &before);
  ASSERT_GT(t_lin.force.norm(), 0.01);
  EXPECT_LE(before, 1e-12);
  ASSERT_GT(hold_until_converged(p, Eigen::Vector3d(0.03, 0.0, kTopZ - depth), t_mr, t_lin), 0);
  const Eigen::Vector3d f_snap = snapshot_force(p.m.snapshot());
  std::cout << "[triangle] 10 mm held, " << p.mr.contacts() << " contact nodes: linear " << t_lin.force.transpose()
            << " N, multirate " << t_mr.force.transpose() << " N, snapshot " << f_snap.transpose() << " N\n";
  EXPECT_LT((t_mr.force - f_snap).norm(), 1e-9 * f_snap.norm());
  EXPECT_GT((t_mr.force - t_lin.force).norm(), 1e-3 * t_lin.force.norm());
  EXPECT_GT(p.m.ticks_nonlinear(), 0u);
}

TEST(MultirateContactsNode, SlideThatChangesThePatchNodesIsPartialFiniteAndContinuous) {
  const Slide r = slide(true);
  // The bound: a node enters or leaves the patch at its edge, where its Wendland weight, and so its linear lambda
  // and (for displacements the linear solve imposes) about its non-linear reaction, go to 0; so a set change may
  // add to the linear model's own step only a small fraction of the force: 5 %, the project's onset step bound.
  const double bound = r.step_lin + 0.05 * r.force_min;
  std::cout << "[slide] 2 cm at 0.05 m/s, 10 mm deep: " << r.partial << " partial ticks of 400; largest one-tick "
            << "force step multirate " << r.step_mr << " N, linear " << r.step_lin << " N, bound " << bound
            << " N (force >= " << r.force_min << " N); allocations in the ticks " << r.allocations << "\n";
  EXPECT_GT(r.partial, 0u) << "the slide changed the patch's nodes: partial matches";
  EXPECT_TRUE(r.finite);
  EXPECT_LE(r.step_mr, bound);
  EXPECT_EQ(r.allocations, 0);
}

// The bench's prediction (targets moved by each node's velocity times the cycle's time) in the node: the local model
// is evaluated closer to its snapshot's state.
TEST(MultirateContactsNode, PredictedTargetsShortenTheExtrapolation) {
  const Slide with = slide(true), without = slide(false);
  std::cout << "[predict] slide, |u_now - u_snapshot| over the common nodes: predicted mean "
            << with.extrapolation_mean * 1e3 << " mm max " << with.extrapolation_max * 1e3 << " mm; not predicted mean "
            << without.extrapolation_mean * 1e3 << " mm max " << without.extrapolation_max * 1e3
            << " mm; largest force step " << with.step_mr << " / " << without.step_mr << " N\n";
  EXPECT_LT(with.extrapolation_mean, without.extrapolation_mean);
}

// The shipped grasp-and-lift (config/trajectories/liver_grasp_lift.csv: the free lobe grasped, lifted 60 degrees in
// 1.5 s, held, released out of the tissue, whose hold fades in 50 ms) with a tracker cycle every 30 ticks: the
// force never steps by more than the linear model's own largest step plus 5 % of the held force. Without the trust
// region the release dropped about 3 N in one tick (the local model, 4 cm from its state with du clamped at 1 cm,
// held 3 N until the contact ended).
TEST(MultirateContactsNode, GraspAndLiftAndReleaseHaveNoForceStep) {
  Scene mr_scene = load_scene(resolve_scene_path("liver_multirate"));
  Scene lin_scene = mr_scene;
  lin_scene.liver.deformation = LiverDeformation::kLinear;
  mr_scene.tools[0].force_limit = lin_scene.tools[0].force_limit = 1000;
  LiverOrgan mr(mr_scene, SURGSIM_TEST_CACHE_DIR, nullptr, false);
  LiverOrgan lin(lin_scene, SURGSIM_TEST_CACHE_DIR, nullptr, false);
  mr.multirate()->set_prediction(true, 0.030);
  const MultiTrajectory traj = MultiTrajectory::load(mr_scene.trajectory);
  Eigen::Vector3d prev_mr = Eigen::Vector3d::Zero(), prev_lin = Eigen::Vector3d::Zero(), held = Eigen::Vector3d::Zero();
  double step_mr = 0, step_lin = 0, step_release = 0;
  bool finite = true;
  for (int k = 0; k <= 4300; ++k) {
    Pose5 pose;
    ASSERT_TRUE(traj.at(0, k * kDt, pose));
    const ToolGeometry g = tool_geometry(mr_scene.tools[0], pose);
    ContactTick t_mr, t_lin;
    mr.step(&g, pose.jaw, kDt, t_mr);
    lin.step(&g, pose.jaw, kDt, t_lin);
    finite = finite && t_mr.device_force.allFinite();
    const double d = (t_mr.force - prev_mr).norm();
    step_mr = std::max(step_mr, d);
    if (k >= 3900) step_release = std::max(step_release, d);
    step_lin = std::max(step_lin, (t_lin.force - prev_lin).norm());
    if (k == 3800) held = t_mr.force;
    prev_mr = t_mr.force;
    prev_lin = t_lin.force;
    if (k % 30 == 0) mr.multirate()->cycle_once();
  }
  const MultirateContacts& m = *mr.multirate();
  const double bound = step_lin + 0.05 * held.norm();
  std::cout << "[lift] held lifted " << held.transpose() << " N; largest one-tick step multirate " << step_mr
            << " N (at the release " << step_release << " N), linear " << step_lin << " N, bound " << bound
            << " N; ticks nonlinear " << m.ticks_nonlinear() << ", partial " << m.ticks_partial() << ", fallback "
            << m.ticks_linear_fallback() << ", blended " << m.ticks_blended() << "\n";
  EXPECT_TRUE(finite);
  EXPECT_GT(held.norm(), 1.0);
  EXPECT_LE(step_mr, bound);
}

// A liver whose surface has more nodes than a BodyState carries is refused at init, naming the scene file, the
// count and the fix (a 30 x 30 x 4 box: 2282 surface nodes).
TEST(MultirateContactsNode, SurfaceOverTheBodyStateCapacityIsRefused) {
  const std::string dir = ::testing::TempDir();
  const std::string msh = dir + "/multirate_big_surface.msh", yaml = dir + "/multirate_big_surface.yaml";
  write_msh(msh, make_box_mesh(30, 30, 4, Eigen::Vector3d(0.2, 0.2, 0.04)));
  std::string text = read_text(std::string(SURGSIM_TEST_CONFIG_DIR) + "/liver_multirate.yaml");
  const auto from = text.find("  generate: liver"), to = text.find("material:");
  ASSERT_TRUE(from != std::string::npos && to != std::string::npos);
  text.replace(from, to - from, "  file: " + msh + "\n");
  text.replace(text.find("trajectory: trajectories/"), 25,
               "trajectory: " + std::string(SURGSIM_TEST_CONFIG_DIR) + "/trajectories/");
  std::ofstream(yaml) << text;
  const Scene scene = load_scene(yaml);
  try {
    LiverOrgan organ(scene, SURGSIM_TEST_CACHE_DIR, nullptr, false);
    FAIL() << "a surface of more than msg::kMaxBodyPoints nodes was accepted";
  } catch (const Error& e) {
    const std::string what = e.what();
    std::cout << "[refused] " << what << "\n";
    EXPECT_NE(what.find("multirate_big_surface.yaml"), std::string::npos);
    EXPECT_NE(what.find("2282"), std::string::npos);
    EXPECT_NE(what.find("target_nodes"), std::string::npos);
  }
}

TEST(MultirateContactsNode, TrackerSleepsWhenNothingChanges) {
  Pair p;
  // No contact: one cycle to rest, then nothing.
  ContactTick t_mr, t_lin;
  p.step(Eigen::Vector3d(0.03, 0.0, kTopZ + 0.01), t_mr, t_lin);
  EXPECT_TRUE(p.m.cycle_once());
  EXPECT_FALSE(p.m.cycle_once());
  EXPECT_EQ(p.m.tracker_cycles(), 1u);
  // A held press: cycles until converged, then nothing until the tool moves.
  press(p, 0.005, t_mr, t_lin);
  ASSERT_GT(hold_until_converged(p, Eigen::Vector3d(0.03, 0.0, kTopZ - 0.005), t_mr, t_lin), 0);
  const std::uint64_t cycles = p.m.tracker_cycles();
  EXPECT_FALSE(p.m.cycle_once());
  EXPECT_EQ(p.m.tracker_cycles(), cycles);
  p.step(Eigen::Vector3d(0.03, 0.0, kTopZ - 0.006), t_mr, t_lin);
  EXPECT_TRUE(p.m.cycle_once());
  EXPECT_EQ(p.m.tracker_cycles(), cycles + 1);
}

// haptic_node --tracker-threads: the tracker thread sets CHOLMOD's OpenMP and OpenBLAS to the threads asked (read
// back from OpenBLAS, process-wide) when it starts; fewer than one is refused.
TEST(MultirateContactsNode, TrackerThreadSetsTheNumericThreadsAsked) {
  using GetThreads = int (*)();
  const auto get = reinterpret_cast<GetThreads>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads"));
  if (get == nullptr) GTEST_SKIP() << "the BLAS in use is not OpenBLAS";
  const Scene scene = test_scene(LiverDeformation::kMultirate);
  {
    LiverOrgan organ(scene, SURGSIM_TEST_CACHE_DIR, nullptr, false, 2);
    EXPECT_EQ(organ.multirate()->numeric_threads(), 2);
    EXPECT_THROW(organ.multirate()->set_numeric_threads(0), Error);
    reinterpret_cast<void (*)(int)>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"))(1);
    organ.multirate()->start();
    // The thread sets it first thing; a bounded wait for the thread to be scheduled, not a timing.
    for (int k = 0; k < 2000 && get() != 2; ++k) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    EXPECT_EQ(get(), 2);
  }
  LiverOrgan organ(scene, SURGSIM_TEST_CACHE_DIR, nullptr, true);
  for (int k = 0; k < 2000 && get() != 1; ++k) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_EQ(get(), 1) << "the default is one thread";
}

}  // namespace
}  // namespace surgsim
