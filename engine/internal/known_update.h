// The known-id update stage: one block of particles against a scan whose observations name their
// landmark slots (every particle holds the same landmarks in the same slots), one observation at
// a time in scan order, in lanes across the particles (engine/landmark_batch.h).
//   propose_block_known  FastSLAM 2.0: each known landmark's observation folded into the
//                        particle's proposal (eq. 61), the log-likelihoods added to the weights,
//                        then the pose drawn (no odometry: the velocities keep their Gaussian
//                        given the pose, engine/proposal.h draw_state) and the covariance
//                        restarted.
//   update_block_known   the landmarks at the (drawn) poses: a new one initialised in every map
//                        (eq. 69-70); a known one gathered into lanes, updated by the vectorised
//                        EKF and scattered back; FastSLAM 1.0 adds each particle's eq. 31 terms
//                        to its weight.
// Each particle sees its observations in scan order, as a per-particle loop would. The landmark
// references gathered for one observation stay valid across the block: an edit makes a
// particle's path its own, and later edits of other maps copy shared nodes, never write them.
// Thread safety: concurrent calls on disjoint blocks with distinct scratch are safe. Costs:
// O(count Z log N) (tree edits) for Z observations, N landmarks; no allocation once the scratch
// has grown, beyond the maps' path copies.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "engine/filter_config.h"
#include "engine/internal/pose_covariance.h"
#include "engine/internal/scan_plan.h"
#include "engine/internal/scan_report.h"
#include "engine/measurement_model.h"
#include "memory/particle_store.h"

namespace fastslam::engine::internal {

// The known-id stage's per-thread buffers.
struct KnownScratch {
  std::vector<double> columns;
  std::vector<memory::Landmark*> edited;
  std::vector<double> pose_only;
};

// What the known-id stage reads besides the particles.
struct KnownInput {
  const RangeBearingModel* sensor = nullptr;
  Eigen::Matrix2d r;
  ExistenceConfig existence;
  std::uint64_t scan_step = 0;
  double weight_scale = 1.0;  // FastSLAM 2.0's weight terms under L + (scale - 1) R (proposal.h)
};

// FastSLAM 2.0, particles [begin, end) of `store` with state dimension N (3 or 5): `draws` holds
// N standard normals per particle.
template <int N>
void propose_block_known(const KnownInput& in, const std::vector<PlannedObservation>& scan,
                         memory::ParticleStore& store, PoseCovariances& covariances,
                         std::size_t begin, std::size_t end, const double* draws,
                         KnownScratch& scratch);

// Particles [begin, end): the scan's landmark updates, each observation's squared Mahalanobis
// distance in the particles' rows of `records` (+inf for a new landmark); with kWeigh
// (FastSLAM 1.0) the weights.
template <bool kWeigh>
void update_block_known(const KnownInput& in, const std::vector<PlannedObservation>& scan,
                        memory::ParticleStore& store, std::size_t begin, std::size_t end,
                        ScanRecords& records, KnownScratch& scratch);

extern template void propose_block_known<3>(const KnownInput&,
                                            const std::vector<PlannedObservation>&,
                                            memory::ParticleStore&, PoseCovariances&, std::size_t,
                                            std::size_t, const double*, KnownScratch&);
extern template void propose_block_known<5>(const KnownInput&,
                                            const std::vector<PlannedObservation>&,
                                            memory::ParticleStore&, PoseCovariances&, std::size_t,
                                            std::size_t, const double*, KnownScratch&);
extern template void update_block_known<true>(const KnownInput&,
                                              const std::vector<PlannedObservation>&,
                                              memory::ParticleStore&, std::size_t, std::size_t,
                                              ScanRecords&, KnownScratch&);
extern template void update_block_known<false>(const KnownInput&,
                                               const std::vector<PlannedObservation>&,
                                               memory::ParticleStore&, std::size_t, std::size_t,
                                               ScanRecords&, KnownScratch&);

}  // namespace fastslam::engine::internal
