// The scan report: what became of each observation of a scan (engine/filter.h
// ObservationAssociation). During the pass every particle writes its row of `ScanRecords` (its
// choice per observation and the squared Mahalanobis distance behind it); after the pass,
// before resampling, `report_scan` reads the row of the particle of highest weight and names
// the landmarks. Recording in every particle costs a few stores per observation, where finding
// the most likely particle first would need a second pass. Thread safety: particles write
// disjoint rows; report_scan is thread-compatible. Costs: O(M Z) memory (kept across scans,
// no allocation once grown); report_scan O(M + Z log N).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "engine/filter.h"
#include "engine/internal/scan_plan.h"
#include "memory/particle_store.h"

namespace fastslam::engine::internal {

class ScanRecords {
 public:
  // Rows for `particles` particles of `observations` observations each; contents unspecified.
  void reset(std::size_t particles, std::size_t observations) {
    observations_ = observations;
    assignment_.resize(particles * observations);
    mahalanobis2_.resize(particles * observations);
  }
  // Particle i's choices (unknown association: a slot or kNewLandmark; unused with known ids,
  // where the plan decides) and distances, one per observation. data() + offset: an empty
  // scan's rows are empty, and indexing an empty vector is undefined.
  std::int64_t* assignment(std::size_t i) noexcept {
    return assignment_.data() + i * observations_;
  }
  double* mahalanobis2(std::size_t i) noexcept { return mahalanobis2_.data() + i * observations_; }
  const std::int64_t* assignment(std::size_t i) const noexcept {
    return assignment_.data() + i * observations_;
  }
  const double* mahalanobis2(std::size_t i) const noexcept {
    return mahalanobis2_.data() + i * observations_;
  }

 private:
  std::size_t observations_ = 0;
  std::vector<std::int64_t> assignment_;
  std::vector<double> mahalanobis2_;
};

// The report of scan `scan_step` for the particle of highest log-weight in `store` (lowest index
// on ties), whose row of `records` the pass wrote and whose map holds the scan's update.
std::vector<ObservationAssociation> report_scan(const memory::ParticleStore& store,
                                                const ScanRecords& records,
                                                const std::vector<PlannedObservation>& scan,
                                                bool known_ids, std::uint64_t scan_step);

}  // namespace fastslam::engine::internal
