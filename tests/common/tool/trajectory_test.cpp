#include "tool/trajectory.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <iterator>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::tool;

namespace surgsim {
namespace {

namespace fs = std::filesystem;

const std::string kTop = "# surgsim-trajectory v1\nt,pitch,yaw,insertion,roll,jaw\n";

fs::path test_dir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = std::string("trajectory_test_") + info->test_suite_name() + "_" + info->name();
  for (char& c : name) {
    if (c == '/') c = '_';
  }
  const fs::path dir = fs::path(::testing::TempDir()) / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string write(const fs::path& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
  return path.string();
}

// The error of Trajectory::load, or (multi) of MultiTrajectory::load; "" when none.
std::string load_error(const std::string& path, bool multi = false) {
  try {
    if (multi) {
      MultiTrajectory::load(path);
    } else {
      Trajectory::load(path);
    }
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof(double)) == 0; }

bool same_pose(const Pose5& a, const Pose5& b) {
  return same_bits(a.pitch, b.pitch) && same_bits(a.yaw, b.yaw) && same_bits(a.insertion, b.insertion) &&
         same_bits(a.roll, b.roll) && same_bits(a.jaw, b.jaw);
}

Pose5 pose(double pitch, double yaw, double insertion, double roll, double jaw) {
  Pose5 p;
  p.pitch = pitch;
  p.yaw = yaw;
  p.insertion = insertion;
  p.roll = roll;
  p.jaw = jaw;
  return p;
}

// ---------------------------------------------------------------------------------------------------------------
// Loading

TEST(TrajectoryLoad, ReadsSamplesCommentsBlankLinesAndCrlf) {
  const fs::path dir = test_dir();
  const std::string path = write(dir / "ok.csv",
                                 "# surgsim-trajectory v1\r\n"
                                 "# made by hand\r\n"
                                 "t,pitch,yaw,insertion,roll,jaw\r\n"
                                 "0,0.1,-0.2,0.05,0,0.5\r\n"
                                 "\r\n"
                                 "  # a comment between samples\n"
                                 "0.5, 0.2, -0.1, +0.07, 1e-3, 0.25\n"
                                 "1.0,0,0,0.1,0,0");  // a complete last line without newline is fine
  const Trajectory t = Trajectory::load(path);
  ASSERT_EQ(t.samples().size(), 3u);
  EXPECT_EQ(t.samples()[0].pose.yaw, -0.2);
  EXPECT_EQ(t.samples()[1].t, 0.5);
  EXPECT_EQ(t.samples()[1].pose.insertion, 0.07);
  EXPECT_EQ(t.samples()[1].pose.roll, 1e-3);
  EXPECT_EQ(t.samples()[2].pose.insertion, 0.1);
  EXPECT_EQ(t.duration(), 1.0);
}

TEST(TrajectoryLoad, SingleSampleIsHeldForever) {
  const fs::path dir = test_dir();
  const Trajectory t = Trajectory::load(write(dir / "one.csv", kTop + "0.25,0,0,0.1,0,0.5\n"));
  EXPECT_EQ(t.duration(), 0.25);
  EXPECT_EQ(t.at(0).insertion, 0.1);
  EXPECT_EQ(t.at(100).insertion, 0.1);
}

struct LoadErrorCase {
  const char* name;
  std::string text;
  int line;  // expected LINE in "FILE:LINE:"
  std::string must_contain;
};
std::ostream& operator<<(std::ostream& os, const LoadErrorCase& c) { return os << c.name; }

// The case's text fails to load with "bad_traj.csv:LINE:" and the expected words.
void expect_load_error(const LoadErrorCase& c, bool multi) {
  const fs::path dir = test_dir();
  const std::string path = write(dir / "bad_traj.csv", c.text);
  const std::string msg = load_error(path, multi);
  ASSERT_FALSE(msg.empty()) << "no error for:\n" << c.text;
  EXPECT_NE(msg.find("bad_traj.csv:" + std::to_string(c.line) + ":"), std::string::npos) << msg;
  EXPECT_NE(msg.find(c.must_contain), std::string::npos) << msg;
}

class TrajectoryError : public ::testing::TestWithParam<LoadErrorCase> {};

TEST_P(TrajectoryError, NamesFileAndLine) { expect_load_error(GetParam(), false); }

INSTANTIATE_TEST_SUITE_P(
    Cases, TrajectoryError,
    ::testing::Values(
        LoadErrorCase{"Empty", "", 1, "empty"},
        LoadErrorCase{"NoMagic", "t,pitch,yaw,insertion,roll,jaw\n0,0,0,0,0,0\n", 1, "not a surgsim trajectory"},
        LoadErrorCase{"MagicWithSpace", "# surgsim-trajectory v1 \n", 1, "must be exactly"},
        LoadErrorCase{"WrongVersion", "# surgsim-trajectory v2\nt,pitch,yaw,insertion,roll,jaw\n0,0,0,0,0,0\n", 1,
                      "unsupported trajectory version 'v2'"},
        LoadErrorCase{"TruncatedMagic", "# surgsim-traj", 1, "truncated"},
        LoadErrorCase{"MissingHeader", "# surgsim-trajectory v1\n", 1, "missing column header"},
        LoadErrorCase{"BadHeader", "# surgsim-trajectory v1\nt,pitch,yaw,depth,roll,jaw\n", 2, "column header"},
        LoadErrorCase{"HeaderWrongOrder", "# surgsim-trajectory v1\nt,yaw,pitch,insertion,roll,jaw\n", 2,
                      "column header"},
        LoadErrorCase{"NoSamples", kTop, 2, "no samples"},
        LoadErrorCase{"NoSamplesOnlyComments", kTop + "# nothing\n\n", 2, "no samples"},
        LoadErrorCase{"TooFewColumns", kTop + "0,0,0,0,0,0\n1,0,0,0,0\n2,0,0,0,0,0\n", 4, "expected 6 columns"},
        LoadErrorCase{"TooManyColumns", kTop + "0,0,0,0,0,0,7\n", 3, "got 7"},
        LoadErrorCase{"NotANumber", kTop + "0,0,0,abc,0,0\n", 3, "column 'insertion': 'abc' is not a number"},
        LoadErrorCase{"EmptyField", kTop + "0,0,,0,0,0\n", 3, "column 'yaw'"},
        LoadErrorCase{"TrailingGarbage", kTop + "0,0,0,0.1x,0,0\n", 3, "not a number"},
        LoadErrorCase{"NaN", kTop + "0,nan,0,0,0,0\n", 3, "column 'pitch': 'nan' is not finite"},
        LoadErrorCase{"Inf", kTop + "0,0,0,0,inf,0\n", 3, "column 'roll': 'inf' is not finite"},
        LoadErrorCase{"Overflow", kTop + "0,0,0,0,0,1e400\n", 3, "column 'jaw'"},
        LoadErrorCase{"NegativeStart", kTop + "-0.1,0,0,0,0,0\n", 3, "negative"},
        LoadErrorCase{"RepeatedTime", kTop + "0,0,0,0,0,0\n0.5,0,0,0,0,0\n0.5,0,0,0,0,0\n", 5,
                      "not after the previous sample's t (line 4)"},
        LoadErrorCase{"DecreasingTime", kTop + "0,0,0,0,0,0\n0.5,0,0,0,0,0\n0.4,0,0,0,0,0\n", 5, "strictly increase"},
        LoadErrorCase{"TruncatedLastLine", kTop + "0,0,0,0.1,0,0\n0.01,0,0,0.1", 4, "truncated last line"},
        LoadErrorCase{"TruncatedMidNumber", kTop + "0,0,0,0.1,0,0\n0.01,0,0,0.1,0,", 4, "truncated"}),
    [](const ::testing::TestParamInfo<LoadErrorCase>& info) { return std::string(info.param.name); });

TEST(TrajectoryLoad, MissingFileNamesIt) {
  const fs::path dir = test_dir();
  const std::string msg = load_error((dir / "absent_traj.csv").string());
  EXPECT_NE(msg.find("absent_traj.csv"), std::string::npos) << msg;
  EXPECT_NE(msg.find("cannot open"), std::string::npos) << msg;
}

// ---------------------------------------------------------------------------------------------------------------
// Interpolation

Trajectory three_samples() {
  Trajectory t;
  t.mutable_samples() = {
      {1.0, pose(0, 0, 0.10, 0, 0.0)}, {2.0, pose(0.2, -0.2, 0.20, 1.0, 0.5)}, {4.0, pose(0.2, -0.2, 0.10, 1.0, 0.5)}};
  return t;
}

TEST(TrajectoryAt, InterpolatesLinearlyBetweenSamples) {
  const Trajectory t = three_samples();
  const Pose5 p = t.at(1.25);
  EXPECT_DOUBLE_EQ(p.pitch, 0.05);
  EXPECT_DOUBLE_EQ(p.yaw, -0.05);
  EXPECT_DOUBLE_EQ(p.insertion, 0.125);
  EXPECT_DOUBLE_EQ(p.roll, 0.25);
  EXPECT_DOUBLE_EQ(p.jaw, 0.125);
  EXPECT_DOUBLE_EQ(t.at(3.0).insertion, 0.15);
  // Exactly the sample at the sample's own time.
  for (const auto& s : t.samples()) EXPECT_TRUE(same_pose(t.at(s.t), s.pose)) << s.t;
}

TEST(TrajectoryAt, ClampsToTheEnds) {
  const Trajectory t = three_samples();
  EXPECT_TRUE(same_pose(t.at(0.0), t.samples().front().pose));
  EXPECT_TRUE(same_pose(t.at(-5.0), t.samples().front().pose));
  EXPECT_TRUE(same_pose(t.at(4.0), t.samples().back().pose));
  EXPECT_TRUE(same_pose(t.at(1e9), t.samples().back().pose));
  EXPECT_TRUE(same_pose(t.at(std::numeric_limits<double>::infinity()), t.samples().back().pose));
  EXPECT_TRUE(same_pose(t.at(std::nan("")), t.samples().front().pose));
  EXPECT_TRUE(same_pose(Trajectory().at(1.0), Pose5()));  // empty: the zero pose
}

TEST(TrajectoryAt, SequentialAndRandomLookupsAgree) {
  // A long trajectory with irregular spacing; compare the cursor path (monotone, then jumps) with a fresh lookup.
  Trajectory t;
  double time = 0.0;
  for (int i = 0; i < 500; ++i) {
    t.mutable_samples().push_back({time, pose(std::sin(i * 0.1), 0, 0.001 * i, 0, 0)});
    time += 0.001 + 0.0005 * (i % 3);
  }
  const double end = t.duration();
  for (int k = 0; k <= 3000; ++k) {  // monotone, finer than the samples
    const double q = end * k / 3000.0;
    Trajectory fresh;
    fresh.mutable_samples() = t.samples();
    ASSERT_TRUE(same_pose(t.at(q), fresh.at(q))) << q;
  }
  for (double q : {0.3, 0.01, 0.5, 0.49, 0.0, end, 0.2}) {  // jumps both ways
    Trajectory fresh;
    fresh.mutable_samples() = t.samples();
    ASSERT_TRUE(same_pose(t.at(q), fresh.at(q))) << q;
  }
}

// ---------------------------------------------------------------------------------------------------------------
// Recording

TEST(TrajectoryRecorder, RecordThenLoadIsBitExact) {
  const fs::path dir = test_dir();
  const std::string path = (dir / "rec.csv").string();
  std::vector<TrajectorySample> in;
  {
    TrajectoryRecorder rec;
    rec.open(path, 7);
    EXPECT_TRUE(rec.is_open());
    for (int i = 0; i < 1000; ++i) {
      TrajectorySample s;
      s.t = i / 1000.0 + i / 3.0e7;  // awkward tick times
      s.pose = pose(std::sin(i * 0.37) / 3.0, -std::cos(i * 0.11) * 3.141592653589793, 0.1 + 1e-17 * i + i / 7.0e4,
                    i * 1e-300, std::nextafter(0.5, 1.0) * (i % 5));
      in.push_back(s);
      ASSERT_TRUE(rec.append(s.t, s.pose));
    }
    rec.close();
    EXPECT_FALSE(rec.is_open());
    EXPECT_EQ(rec.write_errors(), 0);
  }
  const Trajectory out = Trajectory::load(path);
  ASSERT_EQ(out.samples().size(), in.size());
  for (std::size_t i = 0; i < in.size(); ++i) {
    ASSERT_TRUE(same_bits(out.samples()[i].t, in[i].t)) << i;
    ASSERT_TRUE(same_pose(out.samples()[i].pose, in[i].pose)) << i;
    ASSERT_TRUE(same_pose(out.at(in[i].t), in[i].pose)) << i;  // replayed at the recorded ticks: identical
  }
  // The file starts with the versioned header.
  std::ifstream f(path);
  std::string l1, l2;
  std::getline(f, l1);
  std::getline(f, l2);
  EXPECT_EQ(l1, "# surgsim-trajectory v1");
  EXPECT_EQ(l2, "t,pitch,yaw,insertion,roll,jaw");
}

TEST(TrajectoryRecorder, DestroyedWithoutCloseLeavesEveryLineReadable) {
  const fs::path dir = test_dir();
  const std::string path = (dir / "noclose.csv").string();
  {
    TrajectoryRecorder rec;
    rec.open(path, 10);
    for (int i = 0; i < 25; ++i) ASSERT_TRUE(rec.append(0.01 * i, pose(0, 0, 0.1, 0, 0)));
  }  // no close(): the destructor flushes
  EXPECT_EQ(Trajectory::load(path).samples().size(), 25u);
}

TEST(TrajectoryRecorder, CrashLosesOnlyUnflushedLines) {
  // A child process records 25 samples flushing every 10 and dies without closing or flushing stdio:
  // the 20 flushed samples remain and the file loads.
  const fs::path dir = test_dir();
  const std::string path = (dir / "crash.csv").string();
  const pid_t pid = fork();
  ASSERT_NE(pid, -1);
  if (pid == 0) {
    TrajectoryRecorder rec;
    rec.open(path, 10);
    for (int i = 0; i < 25; ++i) rec.append(0.01 * i, pose(0, 0, 0.1, 0, 0));
    _exit(0);
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(Trajectory::load(path).samples().size(), 20u);
}

TEST(TrajectoryRecorder, RefusesSamplesTheLoaderWouldRefuse) {
  const fs::path dir = test_dir();
  const std::string path = (dir / "refuse.csv").string();
  TrajectoryRecorder rec;
  EXPECT_FALSE(rec.append(0, Pose5()));  // not open
  EXPECT_EQ(rec.write_errors(), 1);
  rec.open(path, 0);  // flush_every < 1 means every line
  EXPECT_FALSE(rec.append(-1.0, Pose5()));
  EXPECT_TRUE(rec.append(0.0, Pose5()));
  EXPECT_FALSE(rec.append(0.0, Pose5()));  // not after the previous t
  EXPECT_FALSE(rec.append(0.1, pose(0, std::nan(""), 0, 0, 0)));
  EXPECT_FALSE(rec.append(std::numeric_limits<double>::infinity(), Pose5()));
  EXPECT_TRUE(rec.append(0.1, Pose5()));
  EXPECT_EQ(rec.rejected(), 4);
  // Flushed line by line: readable while still open.
  EXPECT_EQ(Trajectory::load(path).samples().size(), 2u);
  rec.close();
  rec.close();  // twice is harmless
}

TEST(TrajectoryRecorder, OpenFailureIsAnError) {
  const fs::path dir = test_dir();
  TrajectoryRecorder rec;
  try {
    rec.open((dir / "no_such_folder" / "x.csv").string());
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_folder"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(rec.is_open());
}

// ---------------------------------------------------------------------------------------------------------------
// Several instruments (v2)

const std::string kTop2 =
    "# surgsim-trajectory v2\n"
    "t,grasper.pitch,grasper.yaw,grasper.insertion,grasper.roll,grasper.jaw,"
    "probe.pitch,probe.yaw,probe.insertion,probe.roll,probe.jaw\n";

// Writes rows through format_multi and the recorder's file, as the haptic loop's writer thread does.
bool write_row(TrajectoryRecorder& rec, double t, const Pose5* poses, const bool* valid, int n) {
  char buf[TrajectoryRecorder::kMultiLineBytes];
  const int len = rec.format_multi(buf, sizeof buf, t, poses, valid, n);
  if (len <= 0) return false;
  return std::fwrite(buf, 1, static_cast<std::size_t>(len), rec.file()) == static_cast<std::size_t>(len);
}

TEST(MultiTrajectoryRecorder, V2RoundTripIsBitExactIncludingLostSamples) {
  const fs::path dir = test_dir();
  const std::string path = (dir / "two.csv").string();
  const std::vector<std::string> names = {"grasper", "probe", "hook_3"};
  constexpr int kN = 3;
  std::vector<double> times;
  std::vector<std::array<Pose5, kN>> poses;
  std::vector<std::array<bool, kN>> valid;
  {
    TrajectoryRecorder rec;
    rec.open(path, names, 5);
    ASSERT_EQ(rec.instruments(), kN);
    for (int k = 0; k < 800; ++k) {
      const double t = k / 1000.0 + k / 3.0e7;  // awkward tick times
      std::array<Pose5, kN> p;
      std::array<bool, kN> v;
      for (int i = 0; i < kN; ++i) {
        p[static_cast<std::size_t>(i)] =
            pose(std::sin(k * 0.37 + i) / 3.0, -std::cos(k * 0.11) * 3.141592653589793 * (i + 1),
                 0.1 + 1e-17 * k + k / 7.0e4 + i / 9.0, k * 1e-300, std::nextafter(0.5, 1.0) * ((k + i) % 5));
        v[static_cast<std::size_t>(i)] = !((k / 40 + i) % 4 == 3);  // runs of lost input, different per instrument
      }
      if (!v[1]) p[1].yaw = std::nan("");  // a lost instrument's values are not written, whatever they are
      ASSERT_TRUE(write_row(rec, t, p.data(), reinterpret_cast<const bool*>(v.data()), kN)) << k;
      times.push_back(t);
      poses.push_back(p);
      valid.push_back(v);
    }
    rec.close();
    EXPECT_EQ(rec.write_errors(), 0);
    EXPECT_EQ(rec.rejected(), 0);
  }
  std::ifstream f(path);
  std::string l1, l2;
  std::getline(f, l1);
  std::getline(f, l2);
  EXPECT_EQ(l1, "# surgsim-trajectory v2");
  EXPECT_EQ(l2,
            "t,grasper.pitch,grasper.yaw,grasper.insertion,grasper.roll,grasper.jaw,probe.pitch,probe.yaw,"
            "probe.insertion,probe.roll,probe.jaw,hook_3.pitch,hook_3.yaw,hook_3.insertion,hook_3.roll,hook_3.jaw");

  const MultiTrajectory m = MultiTrajectory::load(path);
  ASSERT_EQ(m.names(), names);
  ASSERT_EQ(m.size(), times.size());
  EXPECT_EQ(m.find("probe"), 1);
  EXPECT_EQ(m.find("nobody"), -1);
  int lost = 0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    ASSERT_TRUE(same_bits(m.times()[k], times[k])) << k;
    for (int i = 0; i < kN; ++i) {
      const auto ui = static_cast<std::size_t>(i);
      ASSERT_EQ(m.valid(k, i), valid[k][ui]) << k << " " << i;
      Pose5 got = pose(-7, -7, -7, -7, -7);
      const bool present = m.at(i, times[k], got);  // replayed at the recorded ticks
      ASSERT_EQ(present, valid[k][ui]) << k << " " << i;
      if (present) {
        ASSERT_TRUE(same_pose(m.pose(k, i), poses[k][ui])) << k << " " << i;
        ASSERT_TRUE(same_pose(got, poses[k][ui])) << k << " " << i;
      } else {
        ASSERT_TRUE(same_pose(got, pose(-7, -7, -7, -7, -7))) << "a lost sample leaves the pose untouched";
        ++lost;
      }
    }
  }
  EXPECT_GT(lost, 100);
}

TEST(MultiTrajectoryRecorder, OneInstrumentNamedToolWritesTheV1File) {
  const fs::path dir = test_dir();
  const std::string a = (dir / "a.csv").string();
  const std::string b = (dir / "b.csv").string();
  {
    TrajectoryRecorder old_way, new_way;
    old_way.open(a, 3);
    new_way.open(b, {"tool"}, 3);
    EXPECT_EQ(new_way.instruments(), 1);
    for (int k = 0; k < 50; ++k) {
      const Pose5 p = pose(k / 7.0, -k / 9.0, 0.1 + k / 1e4, 0, 0.5);
      const bool ok = true;
      ASSERT_TRUE(old_way.append(k * 0.001, p));
      ASSERT_TRUE(write_row(new_way, k * 0.001, &p, &ok, 1));
    }
  }
  std::ifstream fa(a, std::ios::binary), fb(b, std::ios::binary);
  const std::string ta((std::istreambuf_iterator<char>(fa)), std::istreambuf_iterator<char>());
  const std::string tb((std::istreambuf_iterator<char>(fb)), std::istreambuf_iterator<char>());
  EXPECT_EQ(ta.rfind("# surgsim-trajectory v1\n", 0), 0u);
  EXPECT_EQ(ta, tb);
  // One instrument with another name is a v2 file.
  TrajectoryRecorder named;
  named.open((dir / "c.csv").string(), {"grasper"}, 1);
  const Pose5 p = pose(0, 0, 0.1, 0, 0.5);
  const bool present = true;
  ASSERT_TRUE(write_row(named, 0.0, &p, &present, 1));
  named.close();
  const MultiTrajectory c = MultiTrajectory::load((dir / "c.csv").string());
  EXPECT_EQ(c.names(), std::vector<std::string>{"grasper"});
  ASSERT_EQ(c.size(), 1u);
  EXPECT_TRUE(same_pose(c.pose(0, 0), p));
}

TEST(MultiTrajectoryRecorder, RefusesRowsTheLoaderWouldRefuse) {
  const fs::path dir = test_dir();
  const std::string path = (dir / "refuse2.csv").string();
  TrajectoryRecorder rec;
  rec.open(path, {"left", "right"}, 1);
  char buf[TrajectoryRecorder::kMultiLineBytes];
  const Pose5 p[2] = {pose(0, 0, 0.1, 0, 0), pose(0, 0, 0.2, 0, 0)};
  const Pose5 bad[2] = {pose(0, 0, 0.1, 0, 0), pose(0, std::nan(""), 0.2, 0, 0)};
  const bool both[2] = {true, true};
  const bool left_only[2] = {true, false};
  EXPECT_GT(rec.format_multi(buf, sizeof buf, 0.0, p, both, 2), 0);
  EXPECT_EQ(rec.format_multi(buf, sizeof buf, 0.0, p, both, 2), 0);   // t not after the previous
  EXPECT_EQ(rec.format_multi(buf, sizeof buf, 0.1, p, both, 1), 0);   // not this file's width
  EXPECT_EQ(rec.format_multi(buf, sizeof buf, 0.1, bad, both, 2), 0);  // a present instrument's NaN
  EXPECT_EQ(rec.format(buf, sizeof buf, 0.1, p[0]), 0);                // one-instrument row in a two-instrument file
  EXPECT_EQ(rec.rejected(), 4);
  EXPECT_EQ(rec.format_multi(buf, 100, 0.1, p, both, 2), 0);  // buffer too small: a write error
  EXPECT_EQ(rec.write_errors(), 1);
  const int len = rec.format_multi(buf, sizeof buf, 0.1, bad, left_only, 2);  // the NaN is in the lost group: fine
  ASSERT_GT(len, 0);
  EXPECT_EQ(std::string(buf, static_cast<std::size_t>(len)), "0.1,0,0,0.1,0,0,,,,,\n");
  // A single instrument cannot record a lost row: a v1 file has none.
  TrajectoryRecorder one;
  one.open((dir / "one.csv").string(), 1);
  const bool lost = false;
  EXPECT_EQ(one.format_multi(buf, sizeof buf, 0.0, p, &lost, 1), 0);
  EXPECT_EQ(one.rejected(), 1);
}

TEST(MultiTrajectoryRecorder, OpenRefusesBadNames) {
  const fs::path dir = test_dir();
  const std::string path = (dir / "names.csv").string();
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{}, "0 instruments"},
      {{"a", "b", "c", "d", "e"}, "5 instruments"},
      {{"a", "a"}, "'a' given twice"},
      {{"a", ""}, "empty name"},
      {{"grasper.left"}, "the character '.'"},
      {{"a b"}, "the character ' '"}};
  for (const auto& [names, want] : cases) {
    SCOPED_TRACE(want);
    TrajectoryRecorder rec;
    try {
      rec.open(path, names);
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(want), std::string::npos) << e.what();
    }
    EXPECT_FALSE(rec.is_open());
  }
}

TEST(MultiTrajectoryAt, LostInputReturnsFalseAndTheValidPoseIsHeldBeforeIt) {
  const fs::path dir = test_dir();
  const std::string path = write(dir / "lost.csv", kTop2 +
                                                       "0,0,0,0.10,0,0.5,,,,,\n"
                                                       "1,0,0,0.20,0,0.5,0,0,0.30,0,0\n"
                                                       "2,,,,,,0,0,0.40,0,0\n"
                                                       "3,0,0,0.40,0,0.5,0,0,0.50,0,0\n"
                                                       "4,  ,,, ,,0,0,0.60,0,0\n");
  const MultiTrajectory m = MultiTrajectory::load(path);
  ASSERT_EQ(m.instruments(), 2);
  ASSERT_EQ(m.size(), 5u);
  EXPECT_FALSE(m.valid(0, 1));
  EXPECT_FALSE(m.valid(2, 0));
  EXPECT_FALSE(m.valid(4, 0));
  EXPECT_TRUE(m.valid(1, 1));
  Pose5 p;
  // The grasper: interpolated between valid samples, held from a valid sample up to a lost one, lost from it on.
  ASSERT_TRUE(m.at(0, 0.5, p));
  EXPECT_DOUBLE_EQ(p.insertion, 0.15);
  ASSERT_TRUE(m.at(0, 1.0, p));
  EXPECT_EQ(p.insertion, 0.20);
  ASSERT_TRUE(m.at(0, 1.5, p));
  EXPECT_EQ(p.insertion, 0.20) << "held, not interpolated towards the lost sample";
  ASSERT_TRUE(m.at(0, std::nextafter(2.0, 0.0), p));
  EXPECT_EQ(p.insertion, 0.20);
  p = pose(9, 9, 9, 9, 9);
  EXPECT_FALSE(m.at(0, 2.0, p));
  EXPECT_FALSE(m.at(0, 2.5, p));
  EXPECT_TRUE(same_pose(p, pose(9, 9, 9, 9, 9))) << "untouched while lost";
  ASSERT_TRUE(m.at(0, 3.0, p));
  EXPECT_EQ(p.insertion, 0.40);
  ASSERT_TRUE(m.at(0, 3.5, p));
  EXPECT_EQ(p.insertion, 0.40);
  EXPECT_FALSE(m.at(0, 4.0, p));
  EXPECT_FALSE(m.at(0, 100.0, p)) << "held after the end: the last sample is lost";
  ASSERT_TRUE(m.at(0, -1.0, p));
  EXPECT_EQ(p.insertion, 0.10);
  // The probe: lost at the start (also before it), then present and interpolated, unaffected by the grasper.
  EXPECT_FALSE(m.at(1, -1.0, p));
  EXPECT_FALSE(m.at(1, 0.0, p));
  EXPECT_FALSE(m.at(1, 0.999, p));
  ASSERT_TRUE(m.at(1, 2.5, p));
  EXPECT_DOUBLE_EQ(p.insertion, 0.45);
  ASSERT_TRUE(m.at(1, 4.5, p));
  EXPECT_EQ(p.insertion, 0.60);
  // No such instrument.
  EXPECT_FALSE(m.at(2, 1.0, p));
  EXPECT_FALSE(m.at(-1, 1.0, p));
}

TEST(MultiTrajectoryAt, SequentialAndRandomLookupsAgree) {
  const fs::path dir = test_dir();
  std::string text = kTop2;
  double time = 0.0;
  for (int k = 0; k < 300; ++k) {
    char line[200];
    const bool lost = k % 17 == 5;
    std::snprintf(line, sizeof line, "%.17g,%.17g,0,%.17g,0,0.5,%s\n", time, std::sin(k * 0.1), 0.001 * k,
                  lost ? ",,,," : "0,0,0.05,0,0");
    text += line;
    time += 0.001 + 0.0005 * (k % 3);
  }
  const std::string path = write(dir / "seq.csv", text);
  const MultiTrajectory m = MultiTrajectory::load(path);
  const double end = m.duration();
  auto check = [&](double q) {
    const MultiTrajectory fresh = MultiTrajectory::load(path);
    for (int i = 0; i < 2; ++i) {
      Pose5 a, b;
      const bool va = m.at(i, q, a);
      const bool vb = fresh.at(i, q, b);
      ASSERT_EQ(va, vb) << q;
      if (va) {
        ASSERT_TRUE(same_pose(a, b)) << q;
      }
    }
  };
  for (int k = 0; k <= 1500; ++k) check(end * k / 1500.0);
  for (double q : {0.3, 0.01, 0.5, 0.49, 0.0, end, 0.2}) check(q);
}

TEST(MultiTrajectoryLoad, V1FileIsOneInstrumentNamedTool) {
  const char* env = std::getenv("SURGSIM_CONFIG_DIR");
  const fs::path cfg = env != nullptr && *env != '\0' ? fs::path(env) : fs::path(SURGSIM_TEST_CONFIG_DIR);
  const std::string path = (cfg / "trajectories" / "liver_poke.csv").string();
  const Trajectory one = Trajectory::load(path);
  const MultiTrajectory m = MultiTrajectory::load(path);
  const MultiTrajectory from = MultiTrajectory::from_single(one);
  for (const MultiTrajectory* x : {&m, &from}) {
    ASSERT_EQ(x->names(), std::vector<std::string>{"tool"});
    ASSERT_EQ(x->size(), one.samples().size());
    EXPECT_EQ(x->duration(), one.duration());
    for (std::size_t k = 0; k < x->size(); ++k) {
      ASSERT_TRUE(x->valid(k, 0));
      ASSERT_TRUE(same_pose(x->pose(k, 0), one.samples()[k].pose)) << k;
    }
    for (int k = -10; k <= 6000; ++k) {  // every millisecond, beyond both ends
      const double q = k * 0.001;
      Pose5 p;
      ASSERT_TRUE(x->at(0, q, p));
      ASSERT_TRUE(same_pose(p, one.at(q))) << q;
    }
  }
  EXPECT_EQ(MultiTrajectory::from_single(one, "grasper").names(), std::vector<std::string>{"grasper"});
}

class MultiTrajectoryError : public ::testing::TestWithParam<LoadErrorCase> {};

TEST_P(MultiTrajectoryError, NamesFileLineAndFix) { expect_load_error(GetParam(), true); }

const std::string kMagic2 = "# surgsim-trajectory v2\n";
const std::string kRow2 = "0,0,0,0.1,0,0.5,0,0,0.1,0,0.5\n";

INSTANTIATE_TEST_SUITE_P(
    Cases, MultiTrajectoryError,
    ::testing::Values(
        LoadErrorCase{"UnknownVersion", "# surgsim-trajectory v3\nt\n", 1, "unsupported trajectory version 'v3'"},
        LoadErrorCase{"V2WithSpace", "# surgsim-trajectory v2 \n", 1, "must be exactly"},
        LoadErrorCase{"MissingHeader", kMagic2, 1, "missing column header"},
        LoadErrorCase{"NoT", kMagic2 + "time,a.pitch,a.yaw,a.insertion,a.roll,a.jaw\n", 2, "first column must be 't'"},
        LoadErrorCase{"OnlyT", kMagic2 + "t\n", 2, "0 columns after 't'"},
        LoadErrorCase{"PartGroup", kMagic2 + "t,a.pitch,a.yaw,a.insertion,a.roll\n", 2, "4 columns after 't'"},
        LoadErrorCase{"V1NamesInV2", kMagic2 + "t,pitch,yaw,insertion,roll,jaw\n", 2,
                      "column 2 is 'pitch', expected NAME.pitch"},
        LoadErrorCase{"EmptyName", kMagic2 + "t,.pitch,.yaw,.insertion,.roll,.jaw\n", 2, "expected NAME.pitch"},
        LoadErrorCase{"MisspelledDof", kMagic2 + "t,a.pitch,a.yw,a.insertion,a.roll,a.jaw\n", 2,
                      "column 3 is 'a.yw', expected 'a.yaw'"},
        LoadErrorCase{"WrongOrder", kMagic2 + "t,a.pitch,a.yaw,a.roll,a.insertion,a.jaw\n", 2,
                      "expected 'a.insertion'"},
        LoadErrorCase{"NameChangesInGroup", kMagic2 + "t,a.pitch,a.yaw,a.insertion,b.roll,b.jaw\n", 2,
                      "column 5 is 'b.roll', expected 'a.roll' (instrument 'a'"},
        LoadErrorCase{"BadNameCharacter", kMagic2 + "t,a b.pitch,a b.yaw,a b.insertion,a b.roll,a b.jaw\n", 2,
                      "instrument name 'a b' (column 2) has the character ' '"},
        LoadErrorCase{"RepeatedName",
                      kMagic2 + "t,a.pitch,a.yaw,a.insertion,a.roll,a.jaw,a.pitch,a.yaw,a.insertion,a.roll,a.jaw\n", 2,
                      "instrument 'a' has two column groups (columns 2-6 and 7-11)"},
        LoadErrorCase{"FiveGroups",
                      kMagic2 + "t,a.pitch,a.yaw,a.insertion,a.roll,a.jaw,b.pitch,b.yaw,b.insertion,b.roll,b.jaw,"
                                "c.pitch,c.yaw,c.insertion,c.roll,c.jaw,d.pitch,d.yaw,d.insertion,d.roll,d.jaw,"
                                "e.pitch,e.yaw,e.insertion,e.roll,e.jaw\n",
                      2, "5 instrument groups, at most 4"},
        LoadErrorCase{"NoSamples", kTop2, 2, "no samples"},
        LoadErrorCase{"TooFewColumns", kTop2 + kRow2 + "1,0,0,0.1,0,0.5\n", 4, "expected 11 columns"},
        LoadErrorCase{"PartlyEmptyGroup", kTop2 + kRow2 + "1,0,0,0.1,0,0.5,0,,0.1,0,\n", 4,
                      "instrument 'probe' has a partly empty group (empty: 'probe.yaw', 'probe.jaw'"},
        LoadErrorCase{"NotANumberNamesInstrumentColumn", kTop2 + "0,0,0,0.1,0,0.5,0,0,x,0,0.5\n", 3,
                      "column 'probe.insertion': 'x' is not a number"},
        LoadErrorCase{"NotFinite", kTop2 + "0,0,0,0.1,0,inf,0,0,0.1,0,0.5\n", 3, "column 'grasper.jaw': 'inf'"},
        LoadErrorCase{"EmptyTime", kTop2 + ",0,0,0.1,0,0.5,0,0,0.1,0,0.5\n", 3, "column 't'"},
        LoadErrorCase{"TruncatedLastLine", kTop2 + kRow2 + "0.01,0,0,0.1,0,0.5,0,0", 4, "truncated last line"},
        LoadErrorCase{"TruncatedInLostGroup", kTop2 + kRow2 + "0.01,0,0,0.1,0,0.5,,,", 4, "truncated last line"},
        LoadErrorCase{"TruncatedLastField", kTop2 + kRow2 + "0.01,0,0,0.1,0,0.5,0,0,0.1,0,", 4, "truncated"},
        LoadErrorCase{"RepeatedTime", kTop2 + kRow2 + "0.5,0,0,0.1,0,0.5,,,,,\n0.5,0,0,0.1,0,0.5,,,,,\n", 5,
                      "not after the previous sample's t (line 4)"},
        LoadErrorCase{"DecreasingTime", kTop2 + kRow2 + "0.5,0,0,0.1,0,0.5,,,,,\n0.4,0,0,0.1,0,0.5,,,,,\n", 5,
                      "strictly increase"},
        LoadErrorCase{"NegativeStart", kTop2 + "-1,0,0,0.1,0,0.5,0,0,0.1,0,0.5\n", 3, "negative"},
        LoadErrorCase{"V1EmptyGroupIsNotLost", kTop + "0,,,,,\n", 3, "column 'pitch': '' is not a number"},
        LoadErrorCase{"V1BadHeader", kTop.substr(0, 24) + "t,grasper.pitch,grasper.yaw,grasper.insertion,grasper.roll,"
                                                          "grasper.jaw\n",
                      2, "expected exactly 't,pitch,yaw,insertion,roll,jaw'"}),
    [](const ::testing::TestParamInfo<LoadErrorCase>& info) { return std::string(info.param.name); });

TEST(MultiTrajectoryLoad, SingleInstrumentReaderRefusesV2) {
  const fs::path dir = test_dir();
  const std::string path = write(dir / "v2.csv", kTop2 + kRow2);
  EXPECT_EQ(MultiTrajectory::load(path).instruments(), 2);
  const std::string msg = load_error(path);
  EXPECT_NE(msg.find("v2.csv:1: unsupported trajectory version 'v2'"), std::string::npos) << msg;
}

// ---------------------------------------------------------------------------------------------------------------
// Shipped trajectories

TEST(ShippedTrajectories, LoadAndAreSmooth) {
  const char* env = std::getenv("SURGSIM_CONFIG_DIR");
  const fs::path cfg = env != nullptr && *env != '\0' ? fs::path(env) : fs::path(SURGSIM_TEST_CONFIG_DIR);
  for (const char* name : {"liver_poke.csv", "plate_poke.csv", "cylinder_press.csv"}) {
    SCOPED_TRACE(name);
    const Trajectory t = Trajectory::load((cfg / "trajectories" / name).string());
    ASSERT_GT(t.samples().size(), 300u);
    EXPECT_EQ(t.samples().front().t, 0.0);
    EXPECT_GE(t.duration(), 4.0);
    for (std::size_t i = 1; i < t.samples().size(); ++i) {
      const auto& a = t.samples()[i - 1];
      const auto& b = t.samples()[i];
      EXPECT_NEAR(b.t - a.t, 0.01, 1e-9);
      EXPECT_LT(std::abs(b.pose.insertion - a.pose.insertion), 1e-3);
    }
  }
  const Trajectory liver = Trajectory::load((cfg / "trajectories" / "liver_poke.csv").string());
  EXPECT_DOUBLE_EQ(liver.at(0).insertion, 0.12);
  EXPECT_DOUBLE_EQ(liver.at(2.0).insertion, 0.175);
  EXPECT_DOUBLE_EQ(liver.at(liver.duration()).insertion, 0.12);
}

}  // namespace
}  // namespace surgsim
