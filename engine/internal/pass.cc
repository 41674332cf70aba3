#include "engine/internal/pass.h"

#include "engine/internal/particle_pass.h"

namespace fastslam::engine::internal {

std::unique_ptr<Pass> make_pass(FilterState& state, const parallel::ParticleKernel& kernel,
                                TrajectoryRecorder& recorder) {
  if (state.config.association == Association::kKnown) {
    return make_known_pass(state, kernel, recorder);
  }
  if (state.config.algorithm == Algorithm::kFastSlam2) {
    return make_fastslam2_pass(state, kernel, recorder);
  }
  return make_fastslam1_pass(state, kernel, recorder);
}

}  // namespace fastslam::engine::internal
