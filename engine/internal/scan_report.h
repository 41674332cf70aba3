// The scan report: what became of each observation of a scan (engine/filter.h
// ObservationAssociation). During the pass every particle writes its row of `ScanRecords` (its
// choice per observation and the squared Mahalanobis distance behind it); after the pass,
// before resampling, `report_scan` reads the row of the particle of highest weight and names
// the landmarks. Recording in every particle costs a store or two per observation, where finding
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

// Observation-major: observation j's entries of all particles are contiguous, so the known-id
// stage, which runs an observation across a block of particles, writes them in one stretch.
class ScanRecords {
 public:
  // Rows for `particles` particles of `observations` observations each; contents unspecified.
  void reset(std::size_t particles, std::size_t observations) {
    particles_ = particles;
    assignment_.resize(particles * observations);
    mahalanobis2_.resize(particles * observations);
  }
  // Observation j's entries: its choice in particle i (unknown association: a slot or
  // kNewLandmark; unused with known ids, where the plan decides) and its distance.
  std::int64_t& assignment(std::size_t j, std::size_t i) noexcept {
    return assignment_[j * particles_ + i];
  }
  double& mahalanobis2(std::size_t j, std::size_t i) noexcept {
    return mahalanobis2_[j * particles_ + i];
  }
  std::int64_t assignment(std::size_t j, std::size_t i) const noexcept {
    return assignment_[j * particles_ + i];
  }
  double mahalanobis2(std::size_t j, std::size_t i) const noexcept {
    return mahalanobis2_[j * particles_ + i];
  }

 private:
  std::size_t particles_ = 0;
  std::vector<std::int64_t> assignment_;
  std::vector<double> mahalanobis2_;
};

// The report of scan `scan_step` for particle `best` of `store` (the set's most likely,
// shared_set.h), whose row of `records` the pass wrote and whose map holds the scan's update.
std::vector<ObservationAssociation> report_scan(const memory::ParticleStore& store, std::size_t best,
                                                const ScanRecords& records,
                                                const std::vector<PlannedObservation>& scan,
                                                bool known_ids, std::uint64_t scan_step);

}  // namespace fastslam::engine::internal
