// Where the tests find ../shared (the data sets beside the repository). CTest passes
// FASTSLAM_SHARED_DIR; tests that need the data skip with a clear message when it is absent.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <string>

namespace fastslam::testing {

// The shared directory, or "" when it is not there.
inline std::string shared_dir() {
  const char* dir = std::getenv("FASTSLAM_SHARED_DIR");
  std::string path = dir != nullptr ? dir : "../shared";
  return std::filesystem::is_directory(path) ? path : std::string();
}

}  // namespace fastslam::testing

// Skips the current test unless ../shared is present; declares `shared` as its path.
#define FASTSLAM_REQUIRE_SHARED(shared)                                                 \
  const std::string shared = ::fastslam::testing::shared_dir();                        \
  if (shared.empty()) {                                                                \
    GTEST_SKIP() << "../shared is absent (set FASTSLAM_SHARED_DIR): this test needs its " \
                    "data sets";                                                       \
  }
