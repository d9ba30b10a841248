// Tool trajectories: CSV with a versioned header, recorded from live input, replayed tick-exact.
//
//   # surgsim-trajectory v1
//   t,pitch,yaw,insertion,roll,jaw
//   0.000000,0.0,0.0,0.05,0.0,0.5
//
// t in s (strictly increasing, first >= 0), angles in rad, insertion in m. Lines starting with '#' after the first
// are comments; blank lines are ignored; CRLF line ends are accepted. Between samples the pose is interpolated
// linearly; before the first it is the first, after the last it is held. The recorder writes each number as the
// shortest text that reads back to the same double, so record -> load replays the poses bit-exactly.
//
// Several instruments, version 2: one column group of five per instrument, named by the scene's tool names:
//
//   # surgsim-trajectory v2
//   t,grasper.pitch,grasper.yaw,grasper.insertion,grasper.roll,grasper.jaw,probe.pitch,probe.yaw,...
//   0,0.1,0,0.05,0,0.5,-0.1,0,0.05,0,0.5
//
// A group of five EMPTY fields says that instrument's input was lost at that sample (recorded live while its device
// was silent): replay zeroes its force and holds it, as the live run did. MultiTrajectory reads both versions (a v1
// file is one instrument named "tool"); the recorder writes v1 for a single instrument named "tool", else v2.
#pragma once
#include <array>
#include <cstdio>
#include <string>
#include <vector>

namespace surgsim::tool {

/// Instruments a scene may have (the scene's tools list; msg::kMaxInstruments of idl/Surgsim.idl).
constexpr int kMaxInstruments = 4;

/// The 5 tool DOF (same meaning and units as msg::ToolPose).
struct Pose5 {
  double pitch = 0;      // rad
  double yaw = 0;        // rad
  double insertion = 0;  // m
  double roll = 0;       // rad
  double jaw = 0;        // rad (0 = closed)
};

struct TrajectorySample {
  double t = 0;  // s
  Pose5 pose;
};

class Trajectory {
 public:
  /// Reads and validates a trajectory file. Throws surgsim::core::Error "FILE:LINE: ..." on a bad header, a wrong
  /// column count, a non-numeric or non-finite value, non-increasing time, or a truncated last line.
  static Trajectory load(const std::string& path);

  const std::vector<TrajectorySample>& samples() const { return samples_; }
  double duration() const { return samples_.empty() ? 0.0 : samples_.back().t; }
  /// Pose at time t (linear interpolation, clamped to the ends; a NaN t gives the first pose). Allocates nothing.
  /// At a sample's own t it returns that sample's pose exactly. O(1) for monotone sequential calls, O(log n)
  /// after a jump. Not thread-safe (moves cursor_): one Trajectory per thread.
  Pose5 at(double t) const;
  std::vector<TrajectorySample>& mutable_samples() { return samples_; }

 private:
  std::vector<TrajectorySample> samples_;
  mutable std::size_t cursor_ = 0;  // last segment used, makes sequential lookups O(1)
};

/// Poses of one or more instruments over time (v1 or v2 file).
class MultiTrajectory {
 public:
  /// Reads and validates a v1 or v2 file. Throws surgsim::core::Error "FILE:LINE: ..." as Trajectory::load does, and
  /// for a v2 header whose groups are not NAME.pitch,NAME.yaw,NAME.insertion,NAME.roll,NAME.jaw, a repeated name, more
  /// than kMaxInstruments groups, or a group partly empty.
  static MultiTrajectory load(const std::string& path);
  /// One instrument named "tool" from a single-instrument trajectory (every sample valid).
  static MultiTrajectory from_single(const Trajectory& trajectory, const std::string& name = "tool");

  int instruments() const { return static_cast<int>(names_.size()); }
  const std::vector<std::string>& names() const { return names_; }
  /// Index of the instrument called `name`, or -1.
  int find(const std::string& name) const;
  std::size_t size() const { return times_.size(); }
  double duration() const { return times_.empty() ? 0.0 : times_.back(); }
  const std::vector<double>& times() const { return times_; }
  /// Sample k of instrument i, and whether its input was present (false: lost).
  const Pose5& pose(std::size_t k, int i) const { return poses_[k * names_.size() + static_cast<std::size_t>(i)]; }
  bool valid(std::size_t k, int i) const { return valid_[k * names_.size() + static_cast<std::size_t>(i)] != 0; }

  /// Pose of instrument i at time t, as Trajectory::at (linear between samples, exact at a sample's own t, clamped to
  /// the ends). Returns false when the instrument's input is lost there: the sample at or before t is lost (then
  /// `pose` is untouched). Between a valid sample and a lost one the valid pose is held (never interpolated towards a
  /// lost sample). No allocation; O(1) for monotone calls. Not thread-safe.
  bool at(int instrument, double t, Pose5& pose) const;

 private:
  std::vector<std::string> names_;
  std::vector<double> times_;
  std::vector<Pose5> poses_;                // sample-major: poses_[k * instruments + i]
  std::vector<unsigned char> valid_;
  mutable std::size_t cursor_ = 0;
};

/// Appends samples to a trajectory file as they arrive, flushing every `flush_every` samples so that a crash
/// loses at most that many. Opened (and its header written) at start-up.
class TrajectoryRecorder {
 public:
  TrajectoryRecorder() = default;
  ~TrajectoryRecorder();
  TrajectoryRecorder(const TrajectoryRecorder&) = delete;
  TrajectoryRecorder& operator=(const TrajectoryRecorder&) = delete;
  /// Creates (truncates) the file and writes and flushes the header. flush_every < 1 means 1.
  /// Throws surgsim::core::Error if the file cannot be created. Closes a previously open file first.
  void open(const std::string& path, int flush_every = 10);
  /// The same for the named instruments: v1 when `names` is {"tool"}, else v2 with one column group per name
  /// (1..kMaxInstruments names). Then use format_multi().
  void open(const std::string& path, const std::vector<std::string>& names, int flush_every = 10);
  /// Instruments of the open file's rows (1 for a v1 file).
  int instruments() const { return instruments_; }
  bool is_open() const { return file_ != nullptr; }
  /// Writes one line; never allocates. Returns false on an I/O error (counted in write_errors(), not thrown),
  /// and on a sample the loader would refuse: a non-finite value, t < 0 or t not after the previous sample
  /// (counted in rejected(), nothing written). Returns false when not open (counted in write_errors()).
  bool append(double t, const Pose5& pose);
  /// Bytes a formatted line may need.
  static constexpr std::size_t kLineBytes = 6 * 32;
  /// Formats one line (with its newline) into buf without writing it, applying the same refusals as append();
  /// returns its length, or 0 when refused (counted). For callers that write through their own queue (the haptic
  /// loop hands lines to a writer thread). No allocation.
  int format(char* buf, std::size_t size, double t, const Pose5& pose) noexcept;
  /// Bytes a formatted multi-instrument line may need.
  static constexpr std::size_t kMultiLineBytes = 32 + 4 * 5 * 32;
  /// One row of every instrument (n = instruments()): poses[i], or five empty fields where valid[i] is false (input
  /// lost). Same refusals as format() (a non-finite value of a valid instrument, t not increasing). No allocation.
  int format_multi(char* buf, std::size_t size, double t, const Pose5* poses, const bool* valid, int n) noexcept;
  /// The open file (for a caller that writes formatted lines itself), or null.
  std::FILE* file() const { return file_; }
  /// Flushes and closes; safe to call twice. The destructor calls it.
  void close();
  long write_errors() const { return write_errors_; }
  long rejected() const { return rejected_; }

 private:
  std::FILE* file_ = nullptr;
  int flush_every_ = 10;
  int since_flush_ = 0;
  long write_errors_ = 0;
  long rejected_ = 0;
  int instruments_ = 1;
  bool has_last_ = false;
  double last_t_ = 0;  // s, t of the last sample written
};

}  // namespace surgsim::tool
