// FastSLAM 1.0's motion normals for the next pass, drawn by a background task on the kernel's
// second thread while the calling thread runs this pass (used when a pass is too light to split
// across threads). The normals are keyed by (seed, step, particle), so who draws them, and when,
// changes no bit. The next pass's controls follow this pass's scan step; their count is guessed
// as this pass's plus one, and steps past the window are drawn in the pass itself.
// Owns two windows (one ready, one being drawn) and the background task; the destructor waits
// for it. Thread safety: one owner thread calls `start_next` and reads `ready()`. Costs:
// start_next O(1) on the caller plus O(M K) on the background thread; the windows' memory is
// reused (kMaxParticles bounds it).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <span>
#include <vector>

#include "engine/motion_batch.h"
#include "parallel/particle_kernel.h"
#include "parallel/random_stream.h"

namespace fastslam::engine::internal {

// One window: the motion normals of steps keys.front(), keys.front() + 1, ... for every particle.
struct MotionNormalsWindow {
  std::vector<std::uint64_t> keys;
  std::size_t lanes = 0;  // the particle count, padded to whole lane groups
  // Step j's first normals at [2 j lanes, 2 j lanes + lanes), its second after them.
  std::vector<double> values;

  // Copies the normals of the leading steps of `steps` that the window holds, for lanes
  // [begin, begin + count), into `out` in the pass's layout (step j's first normals at
  // 2 j count, second at (2 j + 1) count); returns how many steps it copied.
  std::size_t copy(std::span<const std::uint64_t> steps, std::size_t begin, std::size_t count,
                   std::span<double> out) const {
    if (keys.empty() || begin + count > lanes) return 0;
    std::size_t j = 0;
    for (; j < steps.size(); ++j) {
      if (steps[j] < keys.front() || steps[j] - keys.front() >= keys.size()) break;
      const double* from = values.data() + 2 * (steps[j] - keys.front()) * lanes + begin;
      std::copy_n(from, count, out.data() + 2 * j * count);
      std::copy_n(from + lanes, count, out.data() + (2 * j + 1) * count);
    }
    return j;
  }
};

class MotionNormalsAhead {
 public:
  static constexpr std::size_t kMaxParticles = 4096;  // bounds the windows' memory

  // `first_particle`: the set's index of local particle 0 (lane 0).
  MotionNormalsAhead(const parallel::ParticleKernel& kernel, std::uint64_t seed,
                     std::uint32_t first_particle)
      : seed_(seed), first_(first_particle), task_(kernel) {}

  // The window drawn for this pass (empty until the first start_next).
  const MotionNormalsWindow& ready() const { return windows_[ready_]; }

  // Waits for the window being drawn, makes it the ready one, and starts drawing the next:
  // queued + 1 steps from scan_step + 1, for m particles.
  void start_next(std::uint64_t scan_step, std::size_t queued, std::size_t m) {
    task_.wait();
    ready_ = 1 - ready_;
    MotionNormalsWindow& next = windows_[1 - ready_];
    next.keys.resize(queued + 1);
    std::iota(next.keys.begin(), next.keys.end(), scan_step + 1);
    next.lanes = padded_lanes(m);
    next.values.resize(2 * next.keys.size() * next.lanes);
    task_.start([&next, seed = seed_, first = first_] {
      const std::span<double> out(next.values);
      parallel::normal_pairs_for_particles(seed, next.keys, parallel::Purpose::kMotion, first,
                                           next.lanes, out, out.subspan(next.lanes),
                                           2 * next.lanes);
    });
  }

 private:
  std::uint64_t seed_;
  std::uint32_t first_;
  MotionNormalsWindow windows_[2];
  int ready_ = 0;
  parallel::BackgroundTask task_;  // declared after the windows: destroyed, so waited for, first
};

}  // namespace fastslam::engine::internal
