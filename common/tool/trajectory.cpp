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

using namespace surgsim::core;

namespace surgsim::tool {

namespace {

constexpr std::string_view kMagic = "# surgsim-trajectory v1";
constexpr std::string_view kMagicV2 = "# surgsim-trajectory v2";
constexpr std::string_view kMagicPrefix = "# surgsim-trajectory ";
constexpr std::string_view kHeader = "t,pitch,yaw,insertion,roll,jaw";
constexpr std::string_view kHeaderV2 = "t,NAME.pitch,NAME.yaw,NAME.insertion,NAME.roll,NAME.jaw";
constexpr std::string_view kSingleName = "tool";  // the one instrument of a v1 file
constexpr int kDof = 5;                              // columns of one instrument's group
constexpr int kMaxColumns = 1 + kDof * kMaxInstruments;
constexpr const char* kDofNames[kDof] = {"pitch", "yaw", "insertion", "roll", "jaw"};

// A whole field as a double (core/text.h: locale-independent, correctly rounded, one leading '+' accepted); too
// large or too small counts as not finite.
enum class NumberStatus { kOk, kNotNumber, kNotFinite };
NumberStatus parse_double(std::string_view s, double& out) {
  switch (core::text::parse_double(s, out)) {
    case text::Number::kOk: return NumberStatus::kOk;
    case text::Number::kNotNumber: return NumberStatus::kNotNumber;
    default: return NumberStatus::kNotFinite;
  }
}

double lerp(double a, double b, double w) { return a + w * (b - a); }

Pose5 lerp(const Pose5& a, const Pose5& b, double w) {
  Pose5 p;
  p.pitch = lerp(a.pitch, b.pitch, w);
  p.yaw = lerp(a.yaw, b.yaw, w);
  p.insertion = lerp(a.insertion, b.insertion, w);
  p.roll = lerp(a.roll, b.roll, w);
  p.jaw = lerp(a.jaw, b.jaw, w);
  return p;
}

Pose5 pose_of(const double* v) {
  Pose5 p;
  p.pitch = v[0];
  p.yaw = v[1];
  p.insertion = v[2];
  p.roll = v[3];
  p.jaw = v[4];
  return p;
}

// The segment c with time(c) <= t < time(c + 1), for n >= 2 and time(0) < t < time(n - 1): the cached segment or
// the next one (monotone playback), else a binary search.
template <typename TimeOf>
std::size_t find_segment(std::size_t n, std::size_t cursor, double t, const TimeOf& time) {
  const std::size_t c = cursor + 1 < n ? cursor : 0;
  if (time(c) <= t && t < time(c + 1)) return c;
  if (c + 2 < n && time(c + 1) <= t && t < time(c + 2)) return c + 1;
  std::size_t lo = 0, hi = n - 1;  // time(lo) <= t < time(hi)
  while (hi - lo > 1) {
    const std::size_t mid = lo + (hi - lo) / 2;
    (time(mid) <= t ? lo : hi) = mid;
  }
  return lo;
}

// An instrument name as the scene allows it: letters, digits, '_' or '-'. Returns the first other character, or 0.
char bad_name_char(std::string_view name) {
  for (const char ch : name) {
    const bool ok = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == '_' ||
                    ch == '-';
    if (!ok) return ch;
  }
  return 0;
}

// The column names of a file: "t", then the five DOF (v1) or NAME.DOF for each instrument (v2).
std::vector<std::string> column_names(int version, const std::vector<std::string>& names) {
  std::vector<std::string> cols{"t"};
  for (const auto& name : names) {
    for (const char* dof : kDofNames) cols.push_back(version == 1 ? std::string(dof) : name + "." + dof);
  }
  return cols;
}

std::string join(const std::vector<std::string>& v, const char* sep) {
  std::string s;
  for (std::size_t i = 0; i < v.size(); ++i) s += (i > 0 ? sep : "") + v[i];
  return s;
}

// What a trajectory file holds, sample-major (poses[k * names.size() + i]).
struct Table {
  int version = 1;
  std::vector<std::string> names;
  std::vector<double> times;
  std::vector<Pose5> poses;
  std::vector<unsigned char> valid;
};

// Line 1: the versioned magic, exactly. Returns the version (2 only when `multi`).
int read_magic(const std::string& path, std::string_view line, bool complete, bool multi) {
  if (line == kMagic) return 1;
  if (multi && line == kMagicV2) return 2;
  if (!complete && kMagic.substr(0, line.size()) == line) {
    throw_error(path, ":1: truncated first line ", core::text::quote(line), " (the file was cut while being written; ",
                "re-record it)");
  }
  if (line.substr(0, kMagicPrefix.size()) == kMagicPrefix) {
    const std::string_view version = core::text::trim(line.substr(kMagicPrefix.size()));
    if (version == "v1" || (multi && version == "v2")) {
      throw_error(path, ":1: first line ", core::text::quote(line), " has extra spaces (it must be exactly '",
                  version == "v1" ? kMagic : kMagicV2, "')");
    }
    if (multi) {
      throw_error(path, ":1: unsupported trajectory version '", version, "' (this build reads v1: '", kMagic,
                  "' and v2: '", kMagicV2, "'; re-record the trajectory or convert it)");
    }
    throw_error(path, ":1: unsupported trajectory version '", version, "' (this reader takes one instrument, v1: '",
                kMagic, "'; a v2 file with several instruments is read as a multi-instrument trajectory; ",
                "re-record the trajectory or convert it)");
  }
  if (multi) {
    throw_error(path, ":1: not a surgsim trajectory: first line is ", core::text::quote(line),
                " (the first line must be ", "exactly '", kMagic, "' or '", kMagicV2, "', then the column header)");
  }
  throw_error(path, ":1: not a surgsim trajectory: first line is ", core::text::quote(line),
              " (the first line must be ", "exactly '", kMagic, "', then the header '", kHeader, "')");
}

// A v2 column header: "t", then for each instrument NAME.pitch,NAME.yaw,NAME.insertion,NAME.roll,NAME.jaw.
std::vector<std::string> read_header_v2(const std::string& path, int line_no, std::string_view body,
                                        const std::string_view* fields, int count) {
  const std::string fix = std::string(" (the v2 header is 't' then, for each instrument, '") +
                          std::string(kHeaderV2.substr(2)) + "', e.g. 't,grasper.pitch,grasper.yaw," +
                          "grasper.insertion,grasper.roll,grasper.jaw')";
  if (fields[0] != "t") {
    throw_error(path, ":", line_no, ": column header is ", core::text::quote(body), ": the first column must be 't'",
                fix);
  }
  if (count == 1 || (count - 1) % kDof != 0) {
    throw_error(path, ":", line_no, ": column header has ", count - 1, " columns after 't', not a whole group of ",
                kDof, " per instrument", fix);
  }
  const int groups = (count - 1) / kDof;
  if (groups > kMaxInstruments) {
    throw_error(path, ":", line_no, ": column header has ", groups, " instrument groups, at most ", kMaxInstruments,
                " are supported (drop instruments or split the file)");
  }
  std::vector<std::string> names;
  for (int g = 0; g < groups; ++g) {
    std::string name;
    for (int j = 0; j < kDof; ++j) {
      const int c = 1 + g * kDof + j;
      const std::string_view f = fields[c];
      const std::size_t dot = f.rfind('.');
      if (j == 0) {
        if (dot == std::string_view::npos || dot == 0 || f.substr(dot + 1) != kDofNames[0]) {
          throw_error(path, ":", line_no, ": column ", c + 1, " is ", core::text::quote(f),
                      ", expected NAME.pitch, the first column of instrument ", g + 1, "'s group", fix);
        }
        name = std::string(f.substr(0, dot));
        if (const char ch = bad_name_char(name)) {
          throw_error(path, ":", line_no, ": instrument name '", name, "' (column ", c + 1, ") has the character '",
                      ch, "' (use letters, digits, '_' or '-', as the scene's tool names)");
        }
        for (int h = 0; h < g; ++h) {
          if (names[static_cast<std::size_t>(h)] == name) {
            throw_error(path, ":", line_no, ": instrument '", name, "' has two column groups (columns ",
                        2 + h * kDof, "-", 1 + (h + 1) * kDof, " and ", c + 1, "-", c + kDof,
                        ") (each instrument once: rename or drop one)");
          }
        }
        continue;
      }
      const std::string want = name + "." + kDofNames[j];
      if (f != want) {
        throw_error(path, ":", line_no, ": column ", c + 1, " is ", core::text::quote(f), ", expected '", want,
                    "' (instrument '", name, "': its five columns are pitch, yaw, insertion, roll, jaw in this order)");
      }
    }
    names.push_back(std::move(name));
  }
  return names;
}

// Reads and validates a v1 file, or (multi) a v1 or v2 file.
Table read_table(const std::string& path, bool multi) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw_error(path, ": cannot open trajectory file: ", std::strerror(errno),
                " (check the path; record one with --record FILE)");
  }
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw_error(path, ": cannot read trajectory file (I/O error)");

  Table table;
  std::vector<std::string> cols;  // column names once the header is seen
  std::string header;             // the expected header, for messages
  int columns = 0;
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

    if (line_no == 1) {
      table.version = read_magic(path, line, complete, multi);
      continue;
    }

    // Comments and blank lines.
    const std::string_view body = core::text::trim(line);
    if (body.empty() || body.front() == '#') continue;

    // Split into at most kMaxColumns fields (more are counted, not stored).
    std::string_view fields[kMaxColumns];
    const int count = core::text::split_trimmed(body, ',', fields, kMaxColumns);

    // The column header comes once, before any sample.
    if (!header_seen) {
      if (table.version == 1) {
        bool ok = count == 1 + kDof;
        const std::vector<std::string> want = column_names(1, {std::string(kSingleName)});
        for (int c = 0; ok && c < count; ++c) ok = fields[c] == want[static_cast<std::size_t>(c)];
        if (!ok) {
          throw_error(path, ":", line_no, ": column header is ", core::text::quote(body), " (expected exactly '",
                      kHeader, "' after the first line)");
        }
        table.names = {std::string(kSingleName)};
      } else {
        table.names = read_header_v2(path, line_no, body, fields, count);
      }
      cols = column_names(table.version, table.names);
      header = join(cols, ",");
      columns = static_cast<int>(cols.size());
      header_seen = true;
      header_line = line_no;
      continue;
    }

    // A sample: t and, per instrument, five finite numbers or (v2) five empty fields (input lost). A last line
    // without a newline that does not parse was cut mid-write.
    double v[kMaxColumns];
    bool lost[kMaxInstruments] = {};
    NumberStatus status = count == columns ? NumberStatus::kOk : NumberStatus::kNotNumber;
    int bad = -1;          // column of the first bad number
    int partly = -1;       // instrument whose group is partly empty
    for (int c = 0; status == NumberStatus::kOk && partly < 0 && c < columns; ++c) {
      if (table.version == 2 && c > 0 && (c - 1) % kDof == 0) {
        int empty = 0;
        for (int j = 0; j < kDof; ++j) empty += fields[c + j].empty() ? 1 : 0;
        if (empty == kDof) {
          lost[(c - 1) / kDof] = true;
          c += kDof - 1;
          continue;
        }
        if (empty > 0) {
          partly = (c - 1) / kDof;
          break;
        }
      }
      status = parse_double(fields[c], v[c]);
      if (status != NumberStatus::kOk) bad = c;
    }
    if (!complete && (status != NumberStatus::kOk || partly >= 0)) {
      throw_error(path, ":", line_no, ": truncated last line ", core::text::quote(body), " (", std::min(count, columns),
                  " of ", columns, " columns and no newline: the recording was interrupted; delete this line or ",
                  "re-record)");
    }
    if (count != columns) {
      throw_error(path, ":", line_no, ": expected ", columns, " columns (", header, "), got ", count,
                  " (fix or delete this line)");
    }
    if (partly >= 0) {
      std::string empties;
      for (int j = 0; j < kDof; ++j) {
        const int c = 1 + partly * kDof + j;
        if (fields[c].empty()) empties += (empties.empty() ? "'" : ", '") + cols[static_cast<std::size_t>(c)] + "'";
      }
      throw_error(path, ":", line_no, ": instrument '", table.names[static_cast<std::size_t>(partly)],
                  "' has a partly empty group (empty: ", empties, "; a lost sample leaves all five fields empty: ",
                  "fill in the missing values or empty the whole group)");
    }
    if (status == NumberStatus::kNotNumber) {
      throw_error(path, ":", line_no, ": column '", cols[static_cast<std::size_t>(bad)], "': '", fields[bad],
                  "' is not a number (write a plain decimal number, e.g. 0.125)");
    }
    if (status == NumberStatus::kNotFinite) {
      throw_error(path, ":", line_no, ": column '", cols[static_cast<std::size_t>(bad)], "': '", fields[bad],
                  "' is not finite (every value must be a finite number; fix or delete this line)");
    }
    if (table.times.empty() && v[0] < 0) {
      throw_error(path, ":", line_no, ": column 't': ", fields[0],
                  " is negative (time starts at 0 or later; shift the times)");
    }
    if (!table.times.empty() && !(v[0] > table.times.back())) {
      throw_error(path, ":", line_no, ": column 't': ", fields[0], " is not after the previous sample's t (line ",
                  prev_line, ") (times must strictly increase; remove the duplicate or out-of-order line)");
    }
    table.times.push_back(v[0]);
    for (std::size_t i = 0; i < table.names.size(); ++i) {
      table.poses.push_back(lost[i] ? Pose5{} : pose_of(v + 1 + i * kDof));
      table.valid.push_back(lost[i] ? 0 : 1);
    }
    prev_line = line_no;
  }

  const std::string_view magic = table.version == 1 ? kMagic : kMagicV2;
  if (line_no == 0) {
    throw_error(path, ":1: empty trajectory file (the first line must be '", kMagic, "'",
                multi ? std::string(" or '") + std::string(kMagicV2) + "'" : std::string(), ")");
  }
  if (!header_seen) {
    throw_error(path, ":", line_no, ": missing column header (add the line '",
                table.version == 1 ? kHeader : kHeaderV2, "'", table.version == 1 ? "" : " with a group per instrument",
                " after '", magic, "')");
  }
  if (table.times.empty()) {
    throw_error(path, ":", header_line, ": no samples after the column header (add at least one line '", header,
                "', e.g. 0", table.version == 1 ? ",0,0,0.1,0,0.5" : ",0,0,0.1,0,0.5,... (one group per instrument)",
                ")");
  }
  return table;
}

}  // namespace

Trajectory Trajectory::load(const std::string& path) {
  const Table table = read_table(path, false);
  Trajectory traj;
  traj.samples_.reserve(table.times.size());
  for (std::size_t k = 0; k < table.times.size(); ++k) traj.samples_.push_back({table.times[k], table.poses[k]});
  return traj;
}

Pose5 Trajectory::at(double t) const {
  const std::size_t n = samples_.size();
  if (n == 0) return Pose5{};
  if (!(t > samples_.front().t)) return samples_.front().pose;  // also a NaN t
  if (t >= samples_.back().t) return samples_.back().pose;

  // Here n >= 2 and t0 < t < t_last.
  const std::size_t c = find_segment(n, cursor_, t, [this](std::size_t k) { return samples_[k].t; });
  cursor_ = c;
  const TrajectorySample& a = samples_[c];
  const TrajectorySample& b = samples_[c + 1];
  return lerp(a.pose, b.pose, (t - a.t) / (b.t - a.t));
}

MultiTrajectory MultiTrajectory::load(const std::string& path) {
  Table table = read_table(path, true);
  MultiTrajectory m;
  m.names_ = std::move(table.names);
  m.times_ = std::move(table.times);
  m.poses_ = std::move(table.poses);
  m.valid_ = std::move(table.valid);
  return m;
}

MultiTrajectory MultiTrajectory::from_single(const Trajectory& trajectory, const std::string& name) {
  MultiTrajectory m;
  m.names_ = {name};
  for (const auto& s : trajectory.samples()) {
    m.times_.push_back(s.t);
    m.poses_.push_back(s.pose);
    m.valid_.push_back(1);
  }
  return m;
}

int MultiTrajectory::find(const std::string& name) const {
  for (std::size_t i = 0; i < names_.size(); ++i) {
    if (names_[i] == name) return static_cast<int>(i);
  }
  return -1;
}

bool MultiTrajectory::at(int instrument, double t, Pose5& out) const {
  const std::size_t n = times_.size();
  if (n == 0 || instrument < 0 || instrument >= instruments()) return false;
  // The sample at or before t (the first before it, the last after it), and the segment's end when t is inside.
  std::size_t c = 0;
  bool inside = false;
  if (!(t > times_.front())) {  // also a NaN t
    c = 0;
  } else if (t >= times_.back()) {
    c = n - 1;
  } else {
    c = find_segment(n, cursor_, t, [this](std::size_t k) { return times_[k]; });
    cursor_ = c;
    inside = true;
  }
  if (!valid(c, instrument)) return false;
  if (!inside || !valid(c + 1, instrument)) {  // held: never interpolated towards a lost sample
    out = pose(c, instrument);
    return true;
  }
  out = lerp(pose(c, instrument), pose(c + 1, instrument), (t - times_[c]) / (times_[c + 1] - times_[c]));
  return true;
}

TrajectoryRecorder::~TrajectoryRecorder() { close(); }

void TrajectoryRecorder::open(const std::string& path, int flush_every) {
  open(path, std::vector<std::string>{std::string(kSingleName)}, flush_every);
}

void TrajectoryRecorder::open(const std::string& path, const std::vector<std::string>& names, int flush_every) {
  close();
  if (names.empty() || names.size() > static_cast<std::size_t>(kMaxInstruments)) {
    throw_error(path, ": cannot record ", names.size(), " instruments (1 to ", kMaxInstruments, ")");
  }
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (names[i].empty()) throw_error(path, ": instrument ", i, " has an empty name (name every instrument)");
    if (const char ch = bad_name_char(names[i])) {
      throw_error(path, ": instrument name '", names[i], "' has the character '", ch,
                  "' (use letters, digits, '_' or '-', as the scene's tool names)");
    }
    for (std::size_t j = 0; j < i; ++j) {
      if (names[j] == names[i]) throw_error(path, ": instrument name '", names[i], "' given twice (names are keys)");
    }
  }
  const int version = names.size() == 1 && names[0] == kSingleName ? 1 : 2;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) {
    throw_error(path, ": cannot create trajectory file: ", std::strerror(errno),
                " (check that the folder exists and is writable)");
  }
  const std::string head = std::string(version == 1 ? kMagic : kMagicV2) + "\n" +
                           join(column_names(version, names), ",") + "\n";
  if (std::fwrite(head.data(), 1, head.size(), f) != head.size() || std::fflush(f) != 0) {
    const int err = errno;
    std::fclose(f);
    throw_error(path, ": cannot write trajectory header: ", std::strerror(err), " (is the disk full?)");
  }
  file_ = f;
  flush_every_ = std::max(1, flush_every);
  since_flush_ = 0;
  instruments_ = static_cast<int>(names.size());
  has_last_ = false;
  last_t_ = 0;
}

int TrajectoryRecorder::format(char* buf, std::size_t size, double t, const Pose5& pose) noexcept {
  const bool valid = true;
  return format_multi(buf, size, t, &pose, &valid, 1);
}

int TrajectoryRecorder::format_multi(char* buf, std::size_t size, double t, const Pose5* poses, const bool* valid,
                                     int n) noexcept {
  // Refuse what the loader would refuse, so that a recording always replays: a row of another width, a non-finite
  // value of a present instrument, t negative or not increasing. A file of one instrument cannot say "lost" (a v1
  // file has no such row; the recorder does not know here whether its one instrument was written as v1).
  if (n != instruments_ || !std::isfinite(t) || t < 0 || (has_last_ && !(t > last_t_))) {
    ++rejected_;
    return 0;
  }
  for (int i = 0; i < n; ++i) {
    const Pose5& p = poses[i];
    const bool finite = std::isfinite(p.pitch) && std::isfinite(p.yaw) && std::isfinite(p.insertion) &&
                        std::isfinite(p.roll) && std::isfinite(p.jaw);
    if ((valid[i] && !finite) || (!valid[i] && n == 1)) {
      ++rejected_;
      return 0;
    }
  }
  if (size < static_cast<std::size_t>(32 + n * kDof * 32)) {  // kLineBytes for one instrument, kMultiLineBytes for 4
    ++write_errors_;
    return 0;
  }

  // Shortest round-trip text (std::to_chars): locale-independent, bit-exact on reload, no allocation. A double needs
  // at most 24 characters and each field is given 32, so to_chars cannot fail here.
  char* p = buf;
  char* const end = buf + size;
  p = std::to_chars(p, end - 1, t).ptr;
  for (int i = 0; i < n; ++i) {
    const Pose5& q = poses[i];
    const double v[kDof] = {q.pitch, q.yaw, q.insertion, q.roll, q.jaw};
    for (int j = 0; j < kDof; ++j) {
      *p++ = ',';
      if (valid[i]) p = std::to_chars(p, end - 1, v[j]).ptr;  // lost: the field stays empty
    }
  }
  *p++ = '\n';
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

}  // namespace surgsim::tool
