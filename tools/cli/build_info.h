// What this executable is: the project's version, the git commit it was built from (and
// whether tracked files differed from it), the build type and the compiler, fixed at build
// time (cmake/FastslamBuildInfo.cmake), and the SIMD level of the random-stream kernels, chosen
// at run time (parallel/random_stream.h: the CPU's best, or FASTSLAM_ISA). `fastslam --version`
// prints it; metrics.json and sweep.json carry it under "build".
//
// Thread safety: thread-safe. Costs: the first call reads the CPU's features (the kernels'
// choice); later calls O(1) plus the strings they return.
#pragma once

#include <string>

#include <nlohmann/json_fwd.hpp>

namespace fastslam::tools {

struct BuildInfo {
  std::string version;     // "0.1.0" (CMakeLists.txt's project version)
  std::string commit;      // 40 hex digits, or "unknown" outside a git checkout
  bool dirty = false;      // tracked files differed from `commit` when it was built
  std::string build_type;  // CMAKE_BUILD_TYPE: "Release", "Debug", ...
  std::string compiler;    // "GNU 12.2.0"
  std::string simd;        // "avx512", "avx2", "baseline" or "native"
  // The widest vector extension the build's flags allow ("avx512", "avx2", "sse2"): what
  // "native" means, and the floor of a portable build.
  std::string compiled_simd;
};

BuildInfo build_info();

// The text `fastslam --version` prints: a line per fact, the last whether the build has MPI.
std::string version_text();

// {"version", "commit", "dirty", "build_type", "compiler", "simd", "compiled_simd"}.
nlohmann::json build_info_json();

}  // namespace fastslam::tools
