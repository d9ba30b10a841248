// Error type thrown while starting up (loading files, validating input). Never thrown from the haptic loop.
#pragma once
#include <sstream>
#include <stdexcept>
#include <string>

namespace surgsim::core {

/// An error a user can act on: the message names the file (and line or key) at fault and, where possible, the fix.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
};

/// Builds a message from streamable parts: throw_error(path, ":", line, ": bad value ", v).
template <typename... Args>
[[noreturn]] void throw_error(const Args&... args) {
  std::ostringstream os;
  (os << ... << args);
  throw Error(os.str());
}

}  // namespace surgsim::core
