// The particle pass: the one parallel sweep of a step. It carries every block of particles
// through the queued controls (motion_pass.h) and then, on `observe`, the scan: known ids
// (known_update.h), or per particle the candidate search, the joint association
// (engine/association.h), FastSLAM 2.0's draw and the map update (candidate_search.h,
// fs2_draw.h, map_update.h). The algorithm (motion model x FastSLAM 1.0 / 2.0 x known / maximum
// likelihood / sampling association) is chosen once, by `make_pass`, which instantiates the
// matching ParticlePass (particle_pass.h); the stages inside are then fixed at compile time.
// Both calls empty the queue of controls. Thread safety: thread-compatible; a pass runs its
// own parallel work on the kernel (and, for FastSLAM 1.0, a background task drawing the next
// pass's motion normals, waited for by the destructor). Costs: O(M (K + Z log N)) with known
// ids, O(M (K + (Z + k) log N + Z k)) unknown, over the kernel's threads; per-thread scratch is
// kept across passes, so no allocation once it has grown (besides the maps' path copies).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "engine/internal/filter_state.h"
#include "engine/internal/scan_plan.h"
#include "engine/internal/trajectory_recorder.h"
#include "parallel/particle_kernel.h"

namespace fastslam::engine::internal {

class Pass {
 public:
  virtual ~Pass() = default;
  // Runs the queued controls through every particle.
  virtual void drain() = 0;
  // Runs the queued controls and the planned scan of step `scan_step` through every particle.
  virtual void observe(const std::vector<PlannedObservation>& scan, std::uint64_t scan_step) = 0;
  // Whether the last pass's work exceeded FilterConfig::split_seconds (pass_blocks.h). Decides
  // only how work is split, never a result.
  bool heavy() const noexcept { return heavy_; }

 protected:
  bool heavy_ = false;
};

// The pass for state.config. The pass borrows all three arguments for its lifetime.
std::unique_ptr<Pass> make_pass(FilterState& state, const parallel::ParticleKernel& kernel,
                                TrajectoryRecorder& recorder);

}  // namespace fastslam::engine::internal
