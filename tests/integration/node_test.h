// The fixture the integration tests share: a fresh working folder per test, removed when the test passed (kept for
// a look when it failed), and the environment of node processes on a private DDS domain.
#pragma once
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "process.h"
#include "support/test_domain.h"

namespace surgsim::testing {

class NodeTest : public ::testing::Test {
 protected:
  /// Makes TempDir()/surgsim_<name>_<pid> (emptied first) and env_ for a private domain (domain_salt keeps test files
  /// that run in parallel apart).
  void prepare(const std::string& name, int domain_salt) {
    dir_ = std::filesystem::path(::testing::TempDir()) / ("surgsim_" + name + "_" + std::to_string(getpid()));
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    domain_ = test::reserve_test_domain(domain_salt);
    env_ = {"SURGSIM_DOMAIN=" + std::to_string(domain_), "SURGSIM_CONFIG_DIR=" SURGSIM_TEST_CONFIG_DIR,
            "SURGSIM_CACHE_DIR=" SURGSIM_TEST_CACHE_DIR};
  }
  void TearDown() override {
    if (!HasFailure() && !dir_.empty()) std::filesystem::remove_all(dir_);
  }
  static std::string bin(const std::string& name) { return std::string(SURGSIM_TEST_BIN_DIR) + "/" + name; }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  static nlohmann::json json(const std::string& file) { return nlohmann::json::parse(read_file(file)); }

  std::filesystem::path dir_;
  int domain_ = 0;
  std::vector<std::string> env_;
};

}  // namespace surgsim::testing
