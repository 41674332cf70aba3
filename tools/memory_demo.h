// `fastslam memory-demo`: the memory layer at scale, before the engine exists. M particles
// share one N-landmark map; every step each particle changes K random landmarks (path copying)
// and the particles are resampled at random (a gather that shares and releases maps). Prints
// and writes the live memory against one map and against the linear (whole-map copy) baseline.
// Thread safety: runs in its own TBB arena; no shared state.
#pragma once

#include <cstdint>
#include <string>

namespace fastslam::tools {

struct MemoryDemoOptions {
  std::uint64_t landmarks = 1'000'000;
  std::uint32_t particles = 100;
  std::uint32_t steps = 200;
  std::uint32_t updates_per_step = 10;
  std::uint64_t seed = 1;
  int threads = 0;  // 0: all cores
  std::string out;  // directory for metrics.json; empty: none
};

// Runs the demonstration; returns the process exit code.
int run_memory_demo(const MemoryDemoOptions& options);

}  // namespace fastslam::tools
