#include "tool/trajectory.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include "core/error.h"

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

std::string load_error(const std::string& path) {
  try {
    Trajectory::load(path);
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

class TrajectoryError : public ::testing::TestWithParam<LoadErrorCase> {};

TEST_P(TrajectoryError, NamesFileAndLine) {
  const LoadErrorCase& c = GetParam();
  const fs::path dir = test_dir();
  const std::string path = write(dir / "bad_traj.csv", c.text);
  const std::string msg = load_error(path);
  ASSERT_FALSE(msg.empty()) << "no error for:\n" << c.text;
  EXPECT_NE(msg.find("bad_traj.csv:" + std::to_string(c.line) + ":"), std::string::npos) << msg;
  EXPECT_NE(msg.find(c.must_contain), std::string::npos) << msg;
}

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
