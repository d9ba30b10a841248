// Internal to common/mesh (no other folder includes it): what the mesh file formats share. Text helpers, whole-file
// reading and writing, shortest round-trip numbers, and the token Cursor of the .msh and .vtk readers, whose messages
// read "FILE:LINE: what".
#pragma once
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <string_view>

#include "core/error.h"

namespace surgsim::mesh::internal {

// ------------------------------------------------------------------------------------------------------------
// Text helpers

inline bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v'; }

inline bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  }
  return true;
}

// Garbage input ends up in messages: keep them one short printable line.
inline std::string printable(std::string_view s) {
  constexpr std::size_t kMax = 40;
  std::string out;
  for (char c : s.substr(0, kMax)) out += (c >= 0x20 && c < 0x7f) ? c : '?';
  if (s.size() > kMax) out += "...";
  return out;
}

inline std::string read_whole_file(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) core::throw_error(path, ": cannot open mesh file: ", std::strerror(errno));
  std::string text;
  char buf[1 << 16];
  std::size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) text.append(buf, n);
  const bool failed = std::ferror(f) != 0;
  const int err = errno;
  std::fclose(f);
  if (failed) core::throw_error(path, ": cannot read mesh file: ", std::strerror(err));
  return text;
}

inline void write_whole_file(const std::string& path, const std::string& text) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) core::throw_error(path, ": cannot open for writing: ", std::strerror(errno));
  const bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
  const int err = errno;
  if (std::fclose(f) != 0 || !ok) core::throw_error(path, ": cannot write: ", std::strerror(ok ? errno : err));
}

inline void append_number(std::string& out, double v) {
  char buf[64];
  // Shortest representation that reads back to the same double.
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

inline void append_number(std::string& out, std::int64_t v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

// ------------------------------------------------------------------------------------------------------------
// Cursor: whitespace-separated tokens over a whole file in memory, with line numbers for messages.
// Record-oriented formats read a record's first token with token() (which may cross lines) and its other
// fields with the line_* variants, which refuse to run into the next line.

class Cursor {
 public:
  Cursor(const std::string& path, std::string_view text) : path_(path), text_(text) {}

  /// Next token, crossing line ends; empty at end of file.
  std::string_view token() {
    skip_space(true);
    token_line_ = line_;
    const std::size_t begin = pos_;
    while (pos_ < text_.size() && !is_space(text_[pos_])) ++pos_;
    return text_.substr(begin, pos_ - begin);
  }

  /// The next token without consuming it.
  std::string_view peek() {
    const std::size_t pos = pos_;
    const int line = line_, token_line = token_line_;
    const std::string_view t = token();
    pos_ = pos;
    line_ = line;
    token_line_ = token_line;
    return t;
  }

  /// True when only blanks remain on the current line.
  bool at_line_end() {
    skip_space(false);
    return pos_ >= text_.size() || text_[pos_] == '\n';
  }

  /// The rest of the current line (without '\r'), moving to the start of the next one.
  std::string_view rest_of_line() {
    token_line_ = line_;
    const std::size_t begin = pos_;
    while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
    std::string_view s = text_.substr(begin, pos_ - begin);
    if (pos_ < text_.size()) {
      ++pos_;
      ++line_;
    }
    while (!s.empty() && s.back() == '\r') s.remove_suffix(1);
    return s;
  }

  /// Skips the rest of the current line (the next token() starts on a later line).
  void skip_line() {
    while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
  }

  int line() const { return token_line_; }
  std::size_t size() const { return text_.size(); }

  template <typename... Args>
  [[noreturn]] void fail(const Args&... args) const {
    core::throw_error(path_, ":", token_line_, ": ", args...);
  }

  template <typename... Args>
  [[noreturn]] void fail_at(int line, const Args&... args) const {
    core::throw_error(path_, ":", line, ": ", args...);
  }

  [[noreturn]] void fail_eof(std::string_view what) {
    skip_space(true);
    // Report the last line that holds text.
    token_line_ = (!text_.empty() && text_.back() == '\n') ? std::max(1, line_ - 1) : line_;
    fail("unexpected end of file while reading ", what, ": the file is truncated");
  }

  std::int64_t parse_int(std::string_view t, std::string_view what) {
    if (t.empty()) fail_eof(what);
    check_not_section(t, what);
    const char* b = t.data();
    const char* e = t.data() + t.size();
    if (*b == '+') ++b;
    std::int64_t v = 0;
    const auto r = std::from_chars(b, e, v);
    if (r.ec != std::errc() || r.ptr != e) {
      fail("expected an integer (", what, "), got '", printable(t), "'", keyword_hint(t));
    }
    return v;
  }

  double parse_real(std::string_view t, std::string_view what) {
    if (t.empty()) fail_eof(what);
    check_not_section(t, what);
    const char* b = t.data();
    const char* e = t.data() + t.size();
    if (*b == '+') ++b;
    double v = 0;
    const auto r = std::from_chars(b, e, v);
    if (r.ec != std::errc() || r.ptr != e) {
      fail("expected a number (", what, "), got '", printable(t), "'", keyword_hint(t));
    }
    return v;
  }

  std::int64_t integer(std::string_view what) { return parse_int(token(), what); }
  double real(std::string_view what) { return parse_real(token(), what); }

  /// A field that must be on the current line.
  std::int64_t line_int(std::string_view what) {
    if (at_line_end()) fail("line ends early: missing ", what);
    return integer(what);
  }
  double line_real(std::string_view what) {
    if (at_line_end()) fail("line ends early: missing ", what);
    return real(what);
  }

  /// A non-negative count that fits an int (node and element indices are ints).
  int count(std::string_view what, bool on_line = false) {
    const std::int64_t v = on_line ? line_int(what) : integer(what);
    if (v < 0 || v > INT_MAX) fail(what, " is ", v, ": expected a count between 0 and ", INT_MAX);
    return static_cast<int>(v);
  }

  void expect_line_end(std::string_view record) {
    if (!at_line_end()) {
      const std::string_view extra = token();
      fail("unexpected extra value '", printable(extra), "' at the end of ", record);
    }
  }

  /// The first token of record i of n in a section that must end with end_tag.
  std::string_view record_start(std::string_view end_tag, std::int64_t i, std::int64_t n, std::string_view what) {
    const std::string_view t = token();
    if (t.empty()) {
      fail_eof(std::string(what) + " " + std::to_string(i + 1) + " of " + std::to_string(n) + " (" +
               std::string(end_tag) + " missing)");
    }
    if (t[0] == '$') {
      fail("'", printable(t), "' after ", i, " of ", n, " declared ", what,
           "s: the section is shorter than its header says (truncated or edited file?)");
    }
    return t;
  }

  void expect(std::string_view keyword, std::string_view context) {
    const std::string_view t = token();
    if (t.empty()) fail_eof(std::string(keyword) + " " + std::string(context));
    if (!iequals(t, keyword)) fail("expected ", keyword, " ", context, ", got '", printable(t), "'");
  }

 private:
  void skip_space(bool cross_lines) {
    while (pos_ < text_.size() && is_space(text_[pos_])) {
      if (text_[pos_] == '\n') {
        if (!cross_lines) return;
        ++line_;
      }
      ++pos_;
    }
  }

  // A VTK keyword where a number belongs means the previous section is shorter than declared.
  static const char* keyword_hint(std::string_view t) {
    const bool keyword =
        t.size() > 3 && std::all_of(t.begin(), t.end(), [](char c) { return (c >= 'A' && c <= 'Z') || c == '_'; });
    return keyword ? ": a keyword, so the section before it holds fewer values than its header declares" : "";
  }

  // A section tag where a number belongs means the counts and the data disagree.
  void check_not_section(std::string_view t, std::string_view what) {
    if (t[0] == '$') {
      fail("unexpected '", printable(t), "' while reading ", what,
           ": the section holds fewer entries than its header declares (truncated or edited file?)");
    }
  }

  std::string path_;
  std::string_view text_;
  std::size_t pos_ = 0;
  int line_ = 1;
  int token_line_ = 1;
};

}  // namespace surgsim::mesh::internal
