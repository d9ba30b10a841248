// The multirate liver in the real haptic node: config/liver_multirate.yaml replaying its grasp-and-lift at 1 kHz in
// real time (the tracker thread beside the loop, real CHOLMOD, real Fast DDS): the stats show ticks on the non-linear
// model, body states published and no non-finite force, the tracker thread is among the threads --cpu keeps off the
// loop's CPU, and the force on the held lobe is Newton's, measured as multirate_node_bench measures it: the test
// reads the node's ContactFrames, and for the last frame of the hold solves the neo-Hookean Newton problem of that
// tick's contact targets (each entry's node and u_tilde, the imposed displacement the tracker is handed;
// tests/support/newton_reference.h) and compares the frame's force with Newton's reaction sum: within 1 %. The same
// scene with deformation linear on the same trajectory is off by more than 3 % there (5.6 % on the held lobe, as
// multirate_node_bench measures it; 17 % during the lift), so the 1 % tells the models apart.
//
// The trajectory is the shipped one with its lifted hold 4 s longer (5 s in all): the force is Newton's once the
// tracker has converged on the held targets, which takes a few of its cycles after the lift (65-130 ms each alone,
// several times that on a loaded machine). The test asserts no timing: the long hold only makes "converged before the
// hold ends" hold on a slow machine too; a tracker still short of Newton at the end of 5 s fails the test, as it
// should (a tracker that never converges on a held grasp is a bug, not a slow machine).
// Figures are printed: ctest -R integration_haptic_multirate -V.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "dds_support.h"
#include "fem/static_solver.h"
#include "mesher/scene_mesh.h"
#include "node_test.h"
#include "process.h"
#include "scene/scene.h"
#include "support/newton_reference.h"
#include "surgsim_types.h"

namespace surgsim {
namespace {

using eprosima::fastdds::dds::DataReader;
using eprosima::fastdds::dds::DataReaderListener;
using eprosima::fastdds::dds::SampleInfo;
using eprosima::fastrtps::types::ReturnCode_t;
using testing::Process;

constexpr double kHoldFrom = 3.0;   // s, the shipped trajectory's lifted hold (2.9 to 3.9 s) ...
constexpr double kExtraHold = 4.0;  // s, ... lengthened by this
constexpr double kHoldEnd = 3.9 + kExtraHold;

// The --log's force per tick (tick -> fx, fy, fz); `finite` false when any force is not finite.
std::map<long, Eigen::Vector3d> read_forces(const std::string& file, bool& finite) {
  std::map<long, Eigen::Vector3d> out;
  std::istringstream log(testing::read_file(file));
  std::string line;
  std::getline(log, line);  // header
  finite = true;
  while (std::getline(log, line)) {
    std::stringstream ss(line);
    std::string f[6];
    for (auto& x : f) std::getline(ss, x, ',');
    const Eigen::Vector3d v(std::stod(f[2]), std::stod(f[3]), std::stod(f[4]));
    finite = finite && v.allFinite();
    out[std::stol(f[0])] = v;
  }
  return out;
}

// The shipped trajectory (100 rows a second) with the pose of kHoldFrom repeated for kExtraHold more seconds, the rows
// after it shifted by that.
std::string long_hold(const std::string& shipped) {
  std::istringstream in(testing::read_file(shipped));
  std::ostringstream out;
  std::string line;
  bool header = false;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || !header) {
      out << line << "\n";
      if (!line.empty() && line[0] != '#') header = true;  // the column names
      continue;
    }
    const std::size_t comma = line.find(',');
    const double t = std::stod(line.substr(0, comma));
    const std::string pose = line.substr(comma);
    char when[32];
    if (t <= kHoldFrom + 1e-9) {
      out << line << "\n";
      if (std::abs(t - kHoldFrom) < 1e-9) {
        for (int k = 1; k <= static_cast<int>(std::lround(kExtraHold * 100)); ++k) {
          std::snprintf(when, sizeof when, "%.2f", kHoldFrom + k * 0.01);
          out << when << pose << "\n";
        }
      }
    } else {
      std::snprintf(when, sizeof when, "%.2f", t + kExtraHold);
      out << when << pose << "\n";
    }
  }
  return out.str();
}

// The newest ContactFrame with contacts whose sim time is in [from, to] (the DDS listener thread writes, the test
// reads after the run).
class HoldFrames : public DataReaderListener {
 public:
  HoldFrames(double from, double to) : from_(from), to_(to) {}
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    while (reader->take_next_sample(&incoming_, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      std::lock_guard<std::mutex> lock(mutex_);
      if (closed_) continue;
      ++received_;
      const double t = incoming_.sim_time();
      if (t >= from_ && t <= to_ && !incoming_.contacts().empty() && !incoming_.instruments().empty() &&
          (in_window_ == 0 || t > newest_.sim_time())) {
        newest_ = incoming_;
        ++in_window_;
      }
    }
  }
  /// No frame after this (the linear run's on the same domain).
  void close() {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
  }
  msg::ContactFrame newest() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return newest_;
  }
  long received() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return received_;
  }
  long in_window() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return in_window_;
  }

 private:
  double from_, to_;
  msg::ContactFrame incoming_;
  mutable std::mutex mutex_;
  msg::ContactFrame newest_;
  long received_ = 0, in_window_ = 0;
  bool closed_ = false;
};

Eigen::Vector3d vec(const msg::Vec3& v) { return {v.x(), v.y(), v.z()}; }

class HapticMultirate : public testing::NodeTest {
 protected:
  void SetUp() override { prepare("haptic_multirate", 37); }
  int run(const std::vector<std::string>& args, const std::string& out_name) {
    Process p(bin("haptic_node"), args, env_, path(out_name));
    return p.wait(300);
  }
};

TEST_F(HapticMultirate, GraspAndLiftRunsOnTheTrackerAndTheHeldLobeIsNewtons) {
  const std::string config = SURGSIM_TEST_CONFIG_DIR;
  const scene::Scene scene = scene::load_scene(config + "/liver_multirate.yaml");
  std::ofstream(path("grasp_hold.csv")) << long_hold(scene.trajectory);

  // The node's ContactFrames of the hold's last half second (the test's participant on the node's private domain).
  HoldFrames frames(kHoldEnd - 0.5, kHoldEnd - 0.05);
  dds::DdsOptions o;
  o.domain = domain_;
  o.profiles_file = config + "/dds/profiles.xml";
  o.name = "surgsim_test_haptic_multirate";
  dds::Participant participant(o);
  participant.reader(participant.topic(dds::kContactFrameTopic, new msg::ContactFramePubSubType()), dds::kContactReader,
                     &frames);

  // The multirate scene, paced at 1 kHz; the loop on CPU 1 when there are two, every other thread off it.
  const bool two_cpus = std::thread::hardware_concurrency() >= 2;
  std::vector<std::string> args = {
      "--scene", "liver_multirate", "--replay", path("grasp_hold.csv"), "--speed", "1", "--rt-priority", "0",
      "--log",   path("mr.csv"),    "--stats",  path("mr.json")};
  if (two_cpus) args.insert(args.end(), {"--cpu", "1"});
  ASSERT_EQ(run(args, "mr.txt"), 0) << testing::read_file(path("mr.txt"));
  frames.close();
  // The same scene with deformation linear on the same trajectory.
  std::string text = testing::read_file(config + "/liver_multirate.yaml");
  for (const auto& [from, to] : {std::pair<std::string, std::string>{"deformation: multirate", "deformation: linear"},
                                 {"trajectory: trajectories/", "trajectory: " + config + "/trajectories/"}}) {
    const auto at = text.find(from);
    ASSERT_NE(at, std::string::npos) << from << " in liver_multirate.yaml";
    text.replace(at, from.size(), to);
  }
  std::ofstream(path("liver_linear.yaml")) << text;
  ASSERT_EQ(run({"--scene", path("liver_linear.yaml"), "--replay", path("grasp_hold.csv"), "--speed", "max",
                 "--rt-priority", "0", "--log", path("lin.csv"), "--stats", path("lin.json")},
                "lin.txt"),
            0)
      << testing::read_file(path("lin.txt"));

  const nlohmann::json s = json(path("mr.json"));
  ASSERT_TRUE(s.contains("multirate")) << s.dump(1);
  const nlohmann::json& m = s["multirate"];
  std::cout << "[multirate] " << m.dump() << "\n";
  EXPECT_GT(m["ticks_nonlinear"].get<std::uint64_t>(), 0u);
  EXPECT_GT(m["snapshots_published"].get<std::uint64_t>(), 0u);
  EXPECT_GT(m["body_states_published"].get<std::uint64_t>(), 0u);
  EXPECT_EQ(s["nonfinite_rejected"].get<std::uint64_t>(), 0u);
  EXPECT_FALSE(json(path("lin.json")).contains("multirate"));
  if (two_cpus) {
    EXPECT_EQ(s["cpu_placement"]["other_threads_on_loop_cpu"].get<int>(), 0) << s["cpu_placement"].dump();
  }
  bool finite_mr = false, finite_lin = false;
  const auto mr = read_forces(path("mr.csv"), finite_mr);
  const auto lin = read_forces(path("lin.csv"), finite_lin);
  EXPECT_TRUE(finite_mr);
  EXPECT_TRUE(finite_lin);

  // The held lobe against Newton on the targets of the same tick.
  ASSERT_GT(frames.in_window(), 0) << "no ContactFrame of the hold's end received (" << frames.received()
                                   << " frames in all)";
  const msg::ContactFrame f = frames.newest();
  std::vector<fem::ImposedDisplacement> targets;
  for (const msg::ContactEntry& e : f.contacts()) targets.push_back({static_cast<int>(e.node()), vec(e.u_tilde()), 7});
  const mesh::TetMesh mesh = mesher::load_scene_mesh(scene, SURGSIM_TEST_CACHE_DIR, nullptr);
  const test::NewtonReference newton(scene, mesh, SURGSIM_TEST_CACHE_DIR);
  Eigen::Vector3d reference;
  ASSERT_TRUE(newton.tool_force(targets, reference)) << "Newton did not converge on the held targets";
  const Eigen::Vector3d force = vec(f.instruments()[0].force());
  const double error = test::relative_error(force, reference);
  // The linear run's force at the same tick (the log: clamped to the device's 8 N; the contact kinematics, and so
  // the targets, are the linear patch model's in both runs).
  const long tick = std::lround(f.sim_time() * 1e3);
  const auto l = lin.find(tick);
  ASSERT_NE(l, lin.end()) << "tick " << tick << " missing from the linear log";
  const double linear_error = test::relative_error(l->second, reference);
  std::cout << "[multirate] held lobe at " << f.sim_time() << " s (" << targets.size() << " contact nodes, "
            << frames.in_window() << " frames of the hold's end received): node " << force.transpose() << " N, Newton "
            << reference.transpose() << " N, error " << 100 * error << " %; linear " << l->second.transpose()
            << " N, error " << 100 * linear_error << " %\n";
  EXPECT_LT(error, 0.01) << "the held lobe's force is Newton's";
  EXPECT_GT(linear_error, 0.03) << "the linear model is not: the 1 % tells them apart";
}

}  // namespace
}  // namespace surgsim
