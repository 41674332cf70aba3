#include "engine/internal/scan_report.h"

#include "engine/association.h"

namespace fastslam::engine::internal {

std::vector<ObservationAssociation> report_scan(const memory::ParticleStore& store,
                                                std::size_t best, const ScanRecords& records,
                                                const std::vector<PlannedObservation>& scan,
                                                bool known_ids, std::uint64_t scan_step) {
  std::vector<ObservationAssociation> report(scan.size());
  for (std::size_t j = 0; j < scan.size(); ++j) {
    ObservationAssociation& a = report[j];
    a.observation = static_cast<std::uint32_t>(j);
    a.mahalanobis2 = records.mahalanobis2(j, best);
    bool is_new = false;
    if (known_ids) {
      is_new = scan[j].is_new;
      a.landmark_id = scan[j].id;
    } else if (records.assignment(j, best) == kNewLandmark) {
      is_new = true;
      a.landmark_id = scan_step * kLandmarkIdsPerScan + j;  // as map_update.h names it
    } else {
      const auto slot = static_cast<memory::Slot>(records.assignment(j, best));
      a.landmark_id = store.map(best).tree().at(slot).id;
    }
    a.outcome = is_new ? AssociationOutcome::kNew : AssociationOutcome::kAssociated;
  }
  return report;
}

}  // namespace fastslam::engine::internal
