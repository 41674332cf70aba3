// The particle blocks of a pass over m particles: whole groups of kMotionLanes particles (the
// vector width of the control loop, and one 64-byte cache line of a column, so no two tasks
// write the same line), dealt to `tasks` blocks that differ by at most one group. There are
// about m / grain tasks; when there is more than one, their number is rounded up to a multiple
// of the thread count so that no thread waits long for another at the end of a pass. A light
// pass of m <= grain particles runs as one block on the calling thread (a second task would cost
// more than it saves); a heavy one (the previous pass's work exceeded
// FilterConfig::split_seconds) gets at least four blocks per thread whatever the grain, so that a
// thread slowed by another process hands its blocks over. docs/engine.md has the measurements.
// Results never depend on the blocks: each particle's work reads only its own state and streams.
// Thread safety: a value type. Costs: O(1).
#pragma once

#include <algorithm>
#include <cstddef>

#include "engine/motion_batch.h"

namespace fastslam::engine::internal {

struct PassBlocks {
  std::size_t m = 0;
  std::size_t groups = 0;
  std::size_t tasks = 0;

  PassBlocks(std::size_t particles, unsigned threads, std::size_t grain, bool heavy)
      : m(particles), groups((particles + kMotionLanes - 1) / kMotionLanes) {
    tasks = (particles + grain - 1) / grain;
    if (heavy && threads > 1) tasks = std::max<std::size_t>(tasks, 4 * std::size_t{threads});
    if (threads > 1 && tasks > 1) tasks = (tasks + threads - 1) / threads * threads;
    tasks = std::clamp<std::size_t>(tasks, 1, std::max<std::size_t>(groups, 1));
  }
  // First particle of block t (t <= tasks; block t is [begin(t), begin(t + 1))).
  std::size_t begin(std::size_t t) const { return std::min(m, t * groups / tasks * kMotionLanes); }
};

}  // namespace fastslam::engine::internal
