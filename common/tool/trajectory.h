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
#pragma once
#include <array>
#include <cstdio>
#include <string>
#include <vector>

namespace surgsim {

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
  /// Reads and validates a trajectory file. Throws surgsim::Error "FILE:LINE: ..." on a bad header, a wrong
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

/// Appends samples to a trajectory file as they arrive, flushing every `flush_every` samples so that a crash
/// loses at most that many. Opened (and its header written) at start-up.
class TrajectoryRecorder {
 public:
  TrajectoryRecorder() = default;
  ~TrajectoryRecorder();
  TrajectoryRecorder(const TrajectoryRecorder&) = delete;
  TrajectoryRecorder& operator=(const TrajectoryRecorder&) = delete;
  /// Creates (truncates) the file and writes and flushes the header. flush_every < 1 means 1.
  /// Throws surgsim::Error if the file cannot be created. Closes a previously open file first.
  void open(const std::string& path, int flush_every = 10);
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
  bool has_last_ = false;
  double last_t_ = 0;  // s, t of the last sample written
};

}  // namespace surgsim
