#include "engine/internal/scan_report.h"

#include "engine/association.h"

namespace fastslam::engine::internal {

std::vector<ObservationAssociation> report_scan(const memory::ParticleStore& store,
                                                const ScanRecords& records,
                                                const std::vector<PlannedObservation>& scan,
                                                bool known_ids, std::uint64_t scan_step) {
  const std::span<const double> lw = store.log_weight();
  std::size_t best = 0;
  for (std::size_t i = 1; i < lw.size(); ++i) {
    if (lw[i] > lw[best]) best = i;
  }
  const std::int64_t* chosen = records.assignment(best);
  const double* d2 = records.mahalanobis2(best);
  std::vector<ObservationAssociation> report(scan.size());
  for (std::size_t j = 0; j < scan.size(); ++j) {
    ObservationAssociation& a = report[j];
    a.observation = static_cast<std::uint32_t>(j);
    a.mahalanobis2 = d2[j];
    bool is_new = false;
    if (known_ids) {
      is_new = scan[j].is_new;
      a.landmark_id = scan[j].id;
    } else if (chosen[j] == kNewLandmark) {
      is_new = true;
      a.landmark_id = scan_step * kObservationsPerScanLimit + j;  // as map_update.h names it
    } else {
      a.landmark_id = store.map(best).tree().at(static_cast<memory::Slot>(chosen[j])).id;
    }
    a.outcome = is_new ? AssociationOutcome::kNew : AssociationOutcome::kAssociated;
  }
  return report;
}

}  // namespace fastslam::engine::internal
