// The known-id passes: every motion model x FastSLAM 1.0 / 2.0.
#include <memory>
#include <type_traits>

#include "engine/internal/particle_pass.h"
#include "engine/motion_dispatch.h"

namespace fastslam::engine::internal {

std::unique_ptr<Pass> make_known_pass(FilterState& state, const parallel::ParticleKernel& kernel,
                                      TrajectoryRecorder& recorder) {
  return visit_motion(state.config.motion, [&](const auto& motion) -> std::unique_ptr<Pass> {
    using Motion = std::decay_t<decltype(motion)>;
    constexpr Association kKnown = Association::kKnown;
    if (state.config.algorithm == Algorithm::kFastSlam2) {
      return std::make_unique<ParticlePass<Motion, true, kKnown>>(motion, state, kernel, recorder);
    }
    return std::make_unique<ParticlePass<Motion, false, kKnown>>(motion, state, kernel, recorder);
  });
}

}  // namespace fastslam::engine::internal
