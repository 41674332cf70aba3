// A per-process scratch path under the system's temp directory for tests that write files:
// "<tmp>/fastslam_<name>_<pid>", removed first (with anything under it) so a stale run's files
// never leak into this one. Callers add an extension for a file or use it as a directory.
//
// Thread safety: distinct names for concurrent callers. Cost: one filesystem removal.
#pragma once

#include <filesystem>
#include <string>
#include <unistd.h>

namespace fastslam::tools::testing {

inline std::string temp_path(const std::string& name) {
  const auto path = std::filesystem::temp_directory_path() /
                    ("fastslam_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(path);
  return path.string();
}

}  // namespace fastslam::tools::testing
