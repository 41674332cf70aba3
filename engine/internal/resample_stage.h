// The resampling stage after a scan: the configured policy (parallel/resample.h) applied to the
// particles, the scan's evidence (the weights summed to one after the last scan, so their sum now
// is this scan's factor) added to the log-evidence, and, for FastSLAM 2.0 without odometry, the
// velocities' covariance handed from each ancestor to its descendants (it outlives the scan).
// Failures: a NaN or +inf log-weight becomes std::runtime_error (a numerical failure inside the
// filter after the scan was applied); all weights zero (a scan impossible under every particle)
// resets them to uniform and is counted. Thread safety: thread-compatible; runs its own parallel
// work on the kernel. Costs: O(M) plus the gather's map releases; no allocation once grown.
#pragma once

#include <cstdint>

#include "engine/filter_config.h"
#include "engine/internal/filter_state.h"
#include "parallel/particle_kernel.h"
#include "parallel/resample.h"

namespace fastslam::engine::internal {

class ResampleStage {
 public:
  ResampleStage(const FilterConfig& config, const parallel::ParticleKernel& kernel);

  // Resamples state.store after the scan of `scan_step`; `heavy`: the pass was heavy (its many
  // path copies are released in finer tasks).
  void run(FilterState& state, std::uint64_t scan_step, bool heavy);

 private:
  static constexpr std::size_t kScanGrain = 4096;
  const parallel::ParticleKernel& kernel_;
  parallel::Resampler resampler_;
};

}  // namespace fastslam::engine::internal
