#include "tool/trajectory.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string_view>
#include <system_error>

#include "core/error.h"
#include "core/text.h"

namespace surgsim {

namespace {

constexpr std::string_view kMagic = "# surgsim-trajectory v1";
constexpr std::string_view kMagicPrefix = "# surgsim-trajectory ";
constexpr std::string_view kHeader = "t,pitch,yaw,insertion,roll,jaw";
constexpr int kColumns = 6;
constexpr const char* kColumnNames[kColumns] = {"t", "pitch", "yaw", "insertion", "roll", "jaw"};

// A whole field as a double (core/text.h: locale-independent, correctly rounded, one leading '+' accepted); too
// large or too small counts as not finite.
enum class NumberStatus { kOk, kNotNumber, kNotFinite };
NumberStatus parse_double(std::string_view s, double& out) {
  switch (text::parse_double(s, out)) {
    case text::Number::kOk: return NumberStatus::kOk;
    case text::Number::kNotNumber: return NumberStatus::kNotNumber;
    default: return NumberStatus::kNotFinite;
  }
}

double lerp(double a, double b, double w) { return a + w * (b - a); }

}  // namespace

Trajectory Trajectory::load(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw_error(path, ": cannot open trajectory file: ", std::strerror(errno),
                " (check the path; record one with --record FILE)");
  }
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw_error(path, ": cannot read trajectory file (I/O error)");

  Trajectory traj;
  bool header_seen = false;
  int header_line = 0;
  int line_no = 0;
  int prev_line = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    // Split off one line; remember whether it ended with a newline (a recording cut mid-line does not).
    const std::size_t nl = text.find('\n', pos);
    const bool complete = nl != std::string::npos;
    std::string_view line(text.data() + pos, (complete ? nl : text.size()) - pos);
    pos = complete ? nl + 1 : text.size();
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);

    // Line 1: the versioned magic, exactly.
    if (line_no == 1) {
      if (line == kMagic) continue;
      if (!complete && kMagic.substr(0, line.size()) == line) {
        throw_error(path, ":1: truncated first line ", text::quote(line), " (the file was cut while being written; ",
                    "re-record it)");
      }
      if (line.substr(0, kMagicPrefix.size()) == kMagicPrefix) {
        const std::string_view version = text::trim(line.substr(kMagicPrefix.size()));
        if (version == "v1") {
          throw_error(path, ":1: first line ", text::quote(line), " has extra spaces (it must be exactly '", kMagic, "')");
        }
        throw_error(path, ":1: unsupported trajectory version '", version, "' (this build reads v1: '", kMagic,
                    "'; re-record the trajectory or convert it)");
      }
      throw_error(path, ":1: not a surgsim trajectory: first line is ", text::quote(line), " (the first line must be ",
                  "exactly '", kMagic, "', then the header '", kHeader, "')");
    }

    // Comments and blank lines.
    const std::string_view body = text::trim(line);
    if (body.empty() || body.front() == '#') continue;

    // Split into at most kColumns fields (more are counted, not stored).
    std::string_view fields[kColumns];
    const int count = text::split_trimmed(body, ',', fields, kColumns);

    // The column header comes once, before any sample.
    if (!header_seen) {
      bool ok = count == kColumns;
      for (int c = 0; ok && c < kColumns; ++c) ok = fields[c] == kColumnNames[c];
      if (!ok) {
        throw_error(path, ":", line_no, ": column header is ", text::quote(body), " (expected exactly '", kHeader,
                    "' after the first line)");
      }
      header_seen = true;
      header_line = line_no;
      continue;
    }

    // A sample: 6 finite numbers. A last line without a newline that does not parse was cut mid-write.
    double v[kColumns];
    NumberStatus status = count == kColumns ? NumberStatus::kOk : NumberStatus::kNotNumber;
    int bad = -1;
    for (int c = 0; status == NumberStatus::kOk && c < kColumns; ++c) {
      status = parse_double(fields[c], v[c]);
      if (status != NumberStatus::kOk) bad = c;
    }
    if (!complete && status != NumberStatus::kOk) {
      throw_error(path, ":", line_no, ": truncated last line ", text::quote(body), " (", std::min(count, kColumns),
                  " of 6 columns and no newline: the recording was interrupted; delete this line or re-record)");
    }
    if (count != kColumns) {
      throw_error(path, ":", line_no, ": expected 6 columns (", kHeader, "), got ", count,
                  " (fix or delete this line)");
    }
    if (status == NumberStatus::kNotNumber) {
      throw_error(path, ":", line_no, ": column '", kColumnNames[bad], "': '", fields[bad],
                  "' is not a number (write a plain decimal number, e.g. 0.125)");
    }
    if (status == NumberStatus::kNotFinite) {
      throw_error(path, ":", line_no, ": column '", kColumnNames[bad], "': '", fields[bad],
                  "' is not finite (every value must be a finite number; fix or delete this line)");
    }
    if (traj.samples_.empty() && v[0] < 0) {
      throw_error(path, ":", line_no, ": column 't': ", fields[0],
                  " is negative (time starts at 0 or later; shift the times)");
    }
    if (!traj.samples_.empty() && !(v[0] > traj.samples_.back().t)) {
      throw_error(path, ":", line_no, ": column 't': ", fields[0], " is not after the previous sample's t (line ",
                  prev_line, ") (times must strictly increase; remove the duplicate or out-of-order line)");
    }
    TrajectorySample s;
    s.t = v[0];
    s.pose.pitch = v[1];
    s.pose.yaw = v[2];
    s.pose.insertion = v[3];
    s.pose.roll = v[4];
    s.pose.jaw = v[5];
    traj.samples_.push_back(s);
    prev_line = line_no;
  }

  if (line_no == 0) {
    throw_error(path, ":1: empty trajectory file (the first line must be '", kMagic, "')");
  }
  if (!header_seen) {
    throw_error(path, ":", line_no, ": missing column header (add the line '", kHeader, "' after '", kMagic, "')");
  }
  if (traj.samples_.empty()) {
    throw_error(path, ":", header_line, ": no samples after the column header (add at least one line '", kHeader,
                "', e.g. 0,0,0,0.1,0,0.5)");
  }
  return traj;
}

Pose5 Trajectory::at(double t) const {
  const std::size_t n = samples_.size();
  if (n == 0) return Pose5{};
  if (!(t > samples_.front().t)) return samples_.front().pose;  // also a NaN t
  if (t >= samples_.back().t) return samples_.back().pose;

  // Here n >= 2 and t0 < t < t_last: find c with t_c <= t < t_{c+1}. Try the cached segment and the next one
  // (monotone playback), else binary search.
  std::size_t c = cursor_ + 1 < n ? cursor_ : 0;
  if (!(samples_[c].t <= t && t < samples_[c + 1].t)) {
    if (c + 2 < n && samples_[c + 1].t <= t && t < samples_[c + 2].t) {
      ++c;
    } else {
      const auto it = std::upper_bound(samples_.begin(), samples_.end(), t,
                                       [](double x, const TrajectorySample& s) { return x < s.t; });
      c = static_cast<std::size_t>(it - samples_.begin()) - 1;
    }
  }
  cursor_ = c;

  const TrajectorySample& a = samples_[c];
  const TrajectorySample& b = samples_[c + 1];
  const double w = (t - a.t) / (b.t - a.t);
  Pose5 p;
  p.pitch = lerp(a.pose.pitch, b.pose.pitch, w);
  p.yaw = lerp(a.pose.yaw, b.pose.yaw, w);
  p.insertion = lerp(a.pose.insertion, b.pose.insertion, w);
  p.roll = lerp(a.pose.roll, b.pose.roll, w);
  p.jaw = lerp(a.pose.jaw, b.pose.jaw, w);
  return p;
}

TrajectoryRecorder::~TrajectoryRecorder() { close(); }

void TrajectoryRecorder::open(const std::string& path, int flush_every) {
  close();
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) {
    throw_error(path, ": cannot create trajectory file: ", std::strerror(errno),
                " (check that the folder exists and is writable)");
  }
  const std::string head = std::string(kMagic) + "\n" + std::string(kHeader) + "\n";
  if (std::fwrite(head.data(), 1, head.size(), f) != head.size() || std::fflush(f) != 0) {
    const int err = errno;
    std::fclose(f);
    throw_error(path, ": cannot write trajectory header: ", std::strerror(err), " (is the disk full?)");
  }
  file_ = f;
  flush_every_ = std::max(1, flush_every);
  since_flush_ = 0;
  has_last_ = false;
  last_t_ = 0;
}

int TrajectoryRecorder::format(char* buf, std::size_t size, double t, const Pose5& pose) noexcept {
  const double v[kColumns] = {t, pose.pitch, pose.yaw, pose.insertion, pose.roll, pose.jaw};

  // Refuse what the loader would refuse, so that a recording always replays.
  for (double x : v) {
    if (!std::isfinite(x)) {
      ++rejected_;
      return 0;
    }
  }
  if (t < 0 || (has_last_ && !(t > last_t_))) {
    ++rejected_;
    return 0;
  }
  if (size < kLineBytes) {
    ++write_errors_;
    return 0;
  }

  // Shortest round-trip text (std::to_chars): locale-independent, bit-exact on reload, no allocation.
  char* p = buf;
  char* const end = buf + size;
  for (int c = 0; c < kColumns; ++c) {
    const auto r = std::to_chars(p, end - 1, v[c]);  // a double needs at most 24 chars: cannot fail here
    p = r.ptr;
    *p++ = c + 1 < kColumns ? ',' : '\n';
  }
  has_last_ = true;
  last_t_ = t;
  return static_cast<int>(p - buf);
}

bool TrajectoryRecorder::append(double t, const Pose5& pose) {
  if (file_ == nullptr) {
    ++write_errors_;
    return false;
  }
  char buf[kLineBytes];
  const int n = format(buf, sizeof buf, t, pose);
  if (n == 0) return false;
  const std::size_t len = static_cast<std::size_t>(n);
  if (std::fwrite(buf, 1, len, file_) != len) {
    ++write_errors_;
    return false;
  }
  if (++since_flush_ >= flush_every_) {
    since_flush_ = 0;
    if (std::fflush(file_) != 0) {
      ++write_errors_;
      return false;
    }
  }
  return true;
}

void TrajectoryRecorder::close() {
  if (file_ == nullptr) return;
  if (std::fflush(file_) != 0) ++write_errors_;
  if (std::fclose(file_) != 0) ++write_errors_;
  file_ = nullptr;
  since_flush_ = 0;
}

}  // namespace surgsim
