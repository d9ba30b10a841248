// 64-bit FNV-1a hashing, used for scene/mesh/material/tensor identity and cache validation.
#pragma once
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>

namespace surgsim::core {

class Hasher {
 public:
  Hasher& bytes(const void* data, std::size_t n) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < n; ++i) {
      h_ ^= p[i];
      h_ *= 1099511628211ull;
    }
    return *this;
  }
  template <typename T>
  Hasher& value(const T& v) { return bytes(&v, sizeof(T)); }
  Hasher& str(const std::string& s) {
    value<std::uint64_t>(s.size());
    return bytes(s.data(), s.size());
  }
  std::uint64_t digest() const { return h_; }

 private:
  std::uint64_t h_ = 1469598103934665603ull;
};

}  // namespace surgsim::core
