// Trajectory recording (FilterConfig::record_trajectory): the weighted-mean pose after every
// control. A pass that runs queued controls first `begin`s (the weights are snapshot as
// l_i - max l, since the controls do not change them, and exponentiated in finish's parallel
// blocks), lets the motion stage write x, y, cos, sin per control and particle into `buffer()`,
// then `finish`es: the weighted means, per control, over fixed blocks (every control's in one
// parallel call) folded in order as ParticleKernel::reduce folds, so bit-identical for any
// thread count. A rank of a shared particle set (parallel/collective.h) takes the largest
// log-weight of the set and folds every rank's blocks, so every rank records the points one
// process would. Owns the buffer and the points not yet taken; borrows the group.
// Thread safety: thread-compatible; the motion stage writes disjoint parts of the buffer
// concurrently. Costs: begin O(M), finish O(M K) for K controls; the buffer (4 M K doubles) is
// reused.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "engine/filter.h"
#include "parallel/collective.h"
#include "parallel/particle_kernel.h"

namespace fastslam::engine::internal {

class TrajectoryRecorder {
 public:
  // `group`: the ranks sharing the particle set (nullptr: this process holds all of it).
  explicit TrajectoryRecorder(parallel::Collective* group = nullptr) : group_(group) {}

  // Prepares for `controls` controls over the particles with log-weights `log_weight`.
  void begin(std::span<const double> log_weight, std::size_t controls);
  // x, y, cos theta, sin theta of particle i after control k at [(k M + i) * 4].
  double* buffer() { return recorded_.data(); }
  // Appends one point per control; the first is control number `first_control`.
  void finish(const parallel::ParticleKernel& kernel, std::size_t controls,
              std::uint64_t first_control);

  // The points recorded and not taken yet (saved with the state).
  std::vector<TrajectoryPoint>& points() { return points_; }
  const std::vector<TrajectoryPoint>& points() const { return points_; }

 private:
  parallel::Collective* group_;
  std::vector<double> recorded_;
  std::vector<double> weights_;
  std::vector<TrajectoryPoint> points_;
};

}  // namespace fastslam::engine::internal
