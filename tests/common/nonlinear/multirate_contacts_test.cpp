// The multirate liver in the haptic node (liver.deformation: multirate; nonlinear/multirate_contacts.h) on the
// shipped scene config/liver_multirate.yaml (the 1.4k liver, tensors from the cache), with the tool moved over the
// thick part of the liver (liver.yaml's trocar) and a device limit out of the way. The tracker runs without its
// thread: the test replays the thread's cycles on the ticks (LiveCycles: the node's cycle times on this liver,
// 65-130 ms, each cycle's targets taken when it starts and its snapshot used from its end on, predicted by the
// previous cycle's time as the live thread predicts by the measured one), so every figure is deterministic.
//   - a held deep press: before any snapshot the force is the linear model's; once the tracker converged it is the
//     snapshot's reaction sum (Newton's) and differs from the linear force by more than the linear model's error at
//     that depth;
//   - a slide under the press changes the patch's node set: those ticks take the partial match, stay finite and
//     change the force by no more than the linear model's own largest step on the same slide plus 5 % of the force;
//   - every hand-over is rate-limited (at the live cycle times a new snapshot or a node leaving the sliding patch
//     stepped the force by 12 % of it): a contact set that jumps away from the snapshot's nodes fades the local
//     model's correction out over 20 ticks, and a contact that ends and starts again (sooner than a tracker cycle)
//     starts on the linear model;
//   - the tick allocates nothing; the tracker sleeps when nothing changes.
// Figures are printed: ctest -R haptic_liver_multirate -V.
#include "nonlinear/multirate_contacts.h"

#include <dlfcn.h>
#include <gtest/gtest.h>

#include <array>
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

// The tracker thread of the live node replayed on the loop's ticks (MultirateContacts::begin_cycle / finish_cycle):
// a cycle takes the newest targets when it starts and its snapshot is the loop's from the tick after it ends; the
// next cycle starts at once (an idle start, nothing to do, tries again a tick later, as the thread sleeps 1.5 ms).
// The cycles take kCycleMs in turn: the node's cycle times on this liver, 65-130 ms (README, live runs: tracker cycle
// p50 63-67 ms, p99 124-128 ms). Each cycle predicts its targets by the previous cycle's time, the horizon the live
// thread takes from its measured cycle time (prediction on, as in the node).
constexpr std::array<int, 8> kCycleMs = {65, 118, 83, 130, 72, 104, 91, 126};

struct LiveCycles {
  explicit LiveCycles(MultirateContacts& tracker) : m(tracker) {}
  MultirateContacts& m;
  std::size_t next = 0;  // the next cycle's index into kCycleMs
  int duration = 0;      // ticks (ms) of the running cycle
  int left = -1;         // ticks until it ends; -1: none running
  int finished = 0;      // cycles that ran

  // After each tick of the organ: the running cycle ends (its snapshot is the next tick's) or the next one starts.
  // True when a cycle ended.
  bool after_tick() {
    bool ended = false;
    if (left > 0 && --left == 0) {
      m.finish_cycle(1e-3 * duration);
      ++finished;
      left = -1;
      ended = true;
    }
    if (left < 0 && m.begin_cycle()) {
      duration = kCycleMs[next++ % kCycleMs.size()];
      left = duration;
    }
    return ended;
  }
  // Between cycles: the tracker idle (converged at the unchanged targets, nothing started).
  bool idle() const { return left < 0; }
};

struct Pair {
  explicit Pair(ContactModel model = ContactModel::kPatch)
      : mr_scene(with_model(test_scene(LiverDeformation::kMultirate), model)),
        lin_scene(with_model(test_scene(LiverDeformation::kLinear), model)) {}
  Scene mr_scene;
  Scene lin_scene;
  LiverOrgan mr{mr_scene, SURGSIM_TEST_CACHE_DIR, nullptr, false};
  LiverOrgan lin{lin_scene, SURGSIM_TEST_CACHE_DIR, nullptr, false};
  MultirateContacts& m = *mr.multirate();
  LiveCycles live{m};

  // One tick of both organs with a vertical tool whose tip is at `tip` (jaw open), without tracker cycles.
  void step(const Eigen::Vector3d& tip, ContactTick& t_mr, ContactTick& t_lin) {
    const ToolGeometry g = test::vertical_tool(tip);
    mr.step(&g, 0.5, kDt, t_mr);
    lin.step(&g, 0.5, kDt, t_lin);
  }
  // One tick, then the replayed tracker thread's (true when a cycle ended).
  bool live_step(const Eigen::Vector3d& tip, ContactTick& t_mr, ContactTick& t_lin) {
    step(tip, t_mr, t_lin);
    return live.after_tick();
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

// Ticks at `tip` with the replayed tracker thread until it goes idle (converged at the unchanged targets) and the
// 20-tick hand-overs are over; the tracker cycles it took (-1: not within 60 cycles).
int hold_until_converged(Pair& p, const Eigen::Vector3d& tip, ContactTick& t_mr, ContactTick& t_lin) {
  const int start = p.live.finished;
  int idle_ticks = 0;
  for (int k = 0; k < 60 * 130 && idle_ticks < 25; ++k) {
    p.live_step(tip, t_mr, t_lin);
    idle_ticks = p.live.idle() ? idle_ticks + 1 : 0;
  }
  return idle_ticks >= 25 ? p.live.finished - start : -1;
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

// Pressed 10 mm and converged, then 2 cm along x at 0.05 m/s (the patch's edge nodes enter and leave) with the
// replayed tracker thread, its targets predicted by the previous cycle's time (the live node's) or not.
Slide slide(bool predict) {
  Pair p;
  p.m.set_prediction(predict);
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
    p.live.after_tick();
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
// 1.5 s, held, released out of the tissue, whose hold fades in 50 ms) with the replayed tracker thread: the
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
  LiveCycles live(*mr.multirate());
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
    live.after_tick();
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

// The rest surface's height above (x, y): the highest point where the vertical line there crosses its triangles.
double top_z(const LiverOrgan& organ, double x, double y) {
  const Eigen::MatrixX3d& v = organ.mesh().nodes;
  const Eigen::MatrixX3i& tris = organ.surface().tris;
  double top = -HUGE_VAL;
  for (Eigen::Index f = 0; f < tris.rows(); ++f) {
    const Eigen::Vector3d a = v.row(tris(f, 0)), b = v.row(tris(f, 1)), c = v.row(tris(f, 2));
    const double det = (b.x() - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (b.y() - a.y());
    if (std::abs(det) < 1e-14) continue;
    const double s = ((x - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (y - a.y())) / det;
    const double t = ((b.x() - a.x()) * (y - a.y()) - (x - a.x()) * (b.y() - a.y())) / det;
    if (s >= 0 && t >= 0 && s + t <= 1) top = std::max(top, a.z() + s * (b.z() - a.z()) + t * (c.z() - a.z()));
  }
  return top;
}

// The two organs' contact kinematics agree (the same nodes and imposed displacements): then the multirate force
// minus the linear twin's is exactly the local model's correction of the multirate organ's own linear solve.
bool same_kinematics(const LiverOrgan& a, const LiverOrgan& b) {
  const ContactSolution& x = a.liver_contacts().solution();
  const ContactSolution& y = b.liver_contacts().solution();
  if (x.count != y.count) return false;
  for (int l = 0; l < x.count; ++l) {
    const auto sl = static_cast<std::size_t>(l);
    if (x.nodes[sl] != y.nodes[sl] || x.displacement[sl] != y.displacement[sl]) return false;
  }
  return true;
}

// A contact set that jumps: held 10 mm deep and converged (the local model at full weight), the tool jumps 5 cm
// along x in one tick (no node of the snapshot is in the new contact: at 4 cm along y an edge node still was) to 10 mm
// under the surface there, and stays, the replayed tracker cycling on. Until the first snapshot of the new nodes
// arrives the local model cannot be evaluated; its correction of the linear force fades out at the trust region's rate
// (kBlendRate of it a tick, 20 ticks) instead of vanishing in the jump's tick.
TEST(MultirateContactsNode, ContactSetThatJumpsHandsOverAtTheBlendRate) {
  Pair p;
  const double depth = 0.010;
  ContactTick t_mr, t_lin;
  press(p, depth, t_mr, t_lin);
  ASSERT_GT(hold_until_converged(p, Eigen::Vector3d(0.03, 0.0, kTopZ - depth), t_mr, t_lin), 0);
  ASSERT_TRUE(same_kinematics(p.mr, p.lin));
  const Eigen::Vector3d before = t_mr.force - t_lin.force;  // the converged local model's correction, full weight
  ASSERT_GT(before.norm(), 0.02 * t_lin.force.norm()) << "the non-linear correction is worth a hand-over";
  const int cycles0 = p.live.finished;
  const std::uint64_t fallback0 = p.m.ticks_linear_fallback();
  const double x = -0.02, y = 0.0;
  const Eigen::Vector3d there(x, y, top_z(p.mr, x, y) - depth);
  ASSERT_TRUE(std::isfinite(there.z()));
  Eigen::Vector3d prev = before;
  double largest_step = 0, first = 0;
  int ticks = 0, faded_at = -1;
  // Until the first cycle that took the new targets has ended (its snapshot is the next tick's).
  while (p.live.finished == cycles0) {
    p.live_step(there, t_mr, t_lin);
    ++ticks;
    ASSERT_GT(p.mr.contacts(), 0) << "tick " << ticks << ": the contact holds through the jump";
    ASSERT_TRUE(same_kinematics(p.mr, p.lin)) << "tick " << ticks;
    ASSERT_EQ(p.m.ticks_linear_fallback() - fallback0, static_cast<std::uint64_t>(ticks))
        << "tick " << ticks << ": no node of the snapshot is in the contact";
    const Eigen::Vector3d c = t_mr.force - t_lin.force;
    if (ticks == 1) first = c.norm();
    largest_step = std::max(largest_step, (c - prev).norm());
    if (faded_at < 0 && c.norm() <= 1e-12 * t_lin.force.norm()) faded_at = ticks;
    prev = c;
  }
  const double rate = MultirateContacts::kBlendRate;
  std::cout << "[jump] 5 cm in one tick at 10 mm depth: correction before " << before.norm() << " N ("
            << 100 * before.norm() / t_lin.force.norm() << " % of the linear force), after the jump " << first
            << " N; largest step of the correction " << largest_step << " N; faded out at tick " << faded_at << " of "
            << ticks << " before the first snapshot of the new nodes\n";
  EXPECT_GE(first, (1 - rate) * before.norm() * (1 - 1e-9)) << "the correction did not vanish in the jump's tick";
  EXPECT_LE(largest_step, rate * before.norm() * (1 + 1e-9)) << "at most kBlendRate of the correction a tick";
  EXPECT_GE(faded_at, static_cast<int>(std::lround(1 / rate))) << "the hand-over lasts 20 ticks";
}

// A contact that ends starts again on the linear model: held 8 mm deep and converged (the local model at full
// weight), the tool lifted clear for 3 ticks and put back in the same place, sooner than any tracker cycle ends (the
// snapshot of the press still holds the contact's nodes). In the first tick back the local model's correction, computed
// here from that snapshot (snapshot_forces on the contact's nodes and displacements against the linear solve's
// lambdas), has at most kBlendRate of its weight: the take-over from the linear model of a new contact.
TEST(MultirateContactsNode, ContactThatEndsStartsAgainOnTheLinearModel) {
  Pair p;
  const double depth = 0.008;
  const Eigen::Vector3d here(0.03, 0.0, kTopZ - depth), above(0.03, 0.0, kTopZ + 0.003);
  ContactTick t_mr, t_lin;
  press(p, depth, t_mr, t_lin);
  ASSERT_GT(hold_until_converged(p, here, t_mr, t_lin), 0);
  const Eigen::Vector3d held = t_mr.force - t_lin.force;
  ASSERT_GT(held.norm(), 0.02 * t_lin.force.norm());
  const int cycles0 = p.live.finished;
  for (int k = 0; k < 3; ++k) {
    p.live_step(above, t_mr, t_lin);
    ASSERT_EQ(p.mr.contacts(), 0);
  }
  p.live_step(here, t_mr, t_lin);
  ASSERT_EQ(p.live.finished, cycles0) << "no tracker cycle ended in the gap";
  ASSERT_GT(p.mr.contacts(), 0);
  ASSERT_TRUE(same_kinematics(p.mr, p.lin));
  // The local model's full correction this tick, from the snapshot the loop holds.
  const ContactSolution& sol = p.lin.liver_contacts().solution();
  std::array<Eigen::Vector3d, kMaxContacts> local;
  std::array<bool, kMaxContacts> held_nodes;
  double largest = 0;
  const int matched =
      snapshot_forces(p.m.snapshot(), sol.nodes.data(), sol.displacement.data(), sol.count,
                      MultirateContacts::node_options().max_extrapolation, local.data(), held_nodes.data(), largest);
  ASSERT_GT(matched, 0) << "the snapshot of the press holds nodes of the contact";
  Eigen::Vector3d full = Eigen::Vector3d::Zero();  // N, on the tool
  for (int l = 0; l < sol.count; ++l)
    if (held_nodes[static_cast<std::size_t>(l)])
      full -= local[static_cast<std::size_t>(l)] - sol.lambda[static_cast<std::size_t>(l)];
  ASSERT_GT(full.norm(), 0.01 * t_lin.force.norm()) << "the local model corrects the linear force here";
  const Eigen::Vector3d c = t_mr.force - t_lin.force;
  std::cout << "[again] held correction " << held.norm() << " N; back in contact after 3 ticks: " << matched
            << " nodes held by the snapshot, full correction " << full.norm() << " N, applied " << c.norm() << " N\n";
  EXPECT_LE(c.norm(), MultirateContacts::kBlendRate * full.norm() * (1 + 1e-9))
      << "the new contact starts on the linear model";
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
