// The FastSLAM 1.0 passes with unknown association: every motion model x maximum likelihood /
// data association sampling.
#include <memory>
#include <type_traits>

#include "engine/internal/particle_pass.h"
#include "engine/motion_dispatch.h"

namespace fastslam::engine::internal {

std::unique_ptr<Pass> make_fastslam1_pass(FilterState& state,
                                          const parallel::ParticleKernel& kernel,
                                          TrajectoryRecorder& recorder) {
  return visit_motion(state.config.motion, [&](const auto& motion) -> std::unique_ptr<Pass> {
    using Motion = std::decay_t<decltype(motion)>;
    if (state.config.association == Association::kMaximumLikelihood) {
      return std::make_unique<ParticlePass<Motion, false, Association::kMaximumLikelihood>>(
          motion, state, kernel, recorder);
    }
    return std::make_unique<ParticlePass<Motion, false, Association::kDataAssociationSampling>>(
        motion, state, kernel, recorder);
  });
}

}  // namespace fastslam::engine::internal
