#include "core/text.h"

#include <cctype>
#include <charconv>
#include <cmath>
#include <system_error>

namespace surgsim::core::text {

namespace {
bool blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }
}  // namespace

std::string_view trim(std::string_view s) noexcept {
  while (!s.empty() && blank(s.front())) s.remove_prefix(1);
  while (!s.empty() && blank(s.back())) s.remove_suffix(1);
  return s;
}

std::vector<std::string_view> split(std::string_view s, char sep) {
  std::vector<std::string_view> out;
  for (std::size_t start = 0;;) {
    const std::size_t at = s.find(sep, start);
    out.push_back(s.substr(start, at == std::string_view::npos ? std::string_view::npos : at - start));
    if (at == std::string_view::npos) break;
    start = at + 1;
  }
  return out;
}

int split_trimmed(std::string_view s, char sep, std::string_view* out, int capacity) noexcept {
  int count = 0;
  for (std::size_t start = 0;;) {
    const std::size_t at = s.find(sep, start);
    const std::string_view f = trim(s.substr(start, at == std::string_view::npos ? std::string_view::npos : at - start));
    if (count < capacity) out[count] = f;
    ++count;
    if (at == std::string_view::npos) break;
    start = at + 1;
  }
  return count;
}

Number parse_double(std::string_view s, double& out) noexcept {
  s = trim(s);
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  if (s.empty()) return Number::kNotNumber;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), out);
  if (r.ptr != s.data() + s.size()) return Number::kNotNumber;
  if (r.ec == std::errc::result_out_of_range) return Number::kOutOfRange;
  if (r.ec != std::errc()) return Number::kNotNumber;
  return std::isfinite(out) ? Number::kOk : Number::kNotFinite;
}

bool parse_int(std::string_view s, long long& out) noexcept {
  s = trim(s);
  if (s.empty()) return false;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), out);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

std::string lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

std::string quote(std::string_view s, std::size_t max) {
  return "'" + std::string(s.substr(0, max)) + (s.size() > max ? "...'" : "'");
}

}  // namespace surgsim::core::text
