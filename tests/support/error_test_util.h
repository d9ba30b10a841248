// Checking error messages in tests: the message a call throws, and whether it names what it should.
#pragma once
#include <string>

#include "core/error.h"

namespace surgsim::test {

/// The message of the surgsim::core::Error `f` throws ("" if it throws nothing).
template <typename F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const core::Error& e) {
    return e.what();
  }
  return "";
}

inline bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

}  // namespace surgsim::test
