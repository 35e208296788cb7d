// A temporary folder for a test's files, removed with everything in it when its owner is destroyed.
// ctest runs every test case in its own process, so one function-static TempDir per test source is one
// folder per test case; it is removed at exit also after a failed assertion (gtest returns from a failed
// test normally). Only a process killed by a signal leaves its folder behind.
#pragma once

#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <system_error>

#include <gtest/gtest.h>

namespace mc_flow {
namespace test {

class TempDir {
 public:
  /// @brief Creates a new, uniquely named folder `<gtest TempDir>/<prefix>XXXXXX`.
  explicit TempDir(const std::string& prefix) : owner_(::getpid()) {
    std::string pattern = (std::filesystem::path(::testing::TempDir()) / (prefix + "XXXXXX")).string();
    if (::mkdtemp(pattern.data()) == nullptr)
      throw std::runtime_error("cannot create a temporary folder " + pattern + ": " + std::strerror(errno));
    path_ = pattern;
  }
  ~TempDir() {
    // A forked child that exits normally must not delete its parent's folder.
    if (::getpid() != owner_) return;
    std::error_code ignored;  // a destructor must not throw; a folder left behind is harmless
    std::filesystem::remove_all(path_, ignored);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::filesystem::path& path() const { return path_; }

 private:
  pid_t owner_;
  std::filesystem::path path_;
};

}  // namespace test
}  // namespace mc_flow
