// The map update of unknown association, for one particle after its scan's association: the
// chosen landmarks get their EKF update at the particle's (drawn) pose and their index entries
// move with their means; with LoopClosureConfig::merge_gate, a confirmed twin of a chosen landmark
// (another candidate of its observation, within the gate of it) is merged into it; every landmark
// in the sensor's footprint that was not chosen loses existence log-odds and is removed below the
// bound (negative information, eq. 73-75), and under data association sampling with a detection
// model each confirmed one of them is a missed detection in the particle's weight; then the new
// landmarks enter the map and the index, with ids (scan step) * 2^20 + (observation index). The
// particle's memory::ParticleMap keeps its tree and spatial index in step; an index entry's extent
// is its landmark's largest covariance eigenvalue, `largest_variance`. Thread safety: writes only
// the particle's map; concurrent calls on distinct particles with distinct scratch are safe. Costs:
// O((Z + k) log N) for Z observations and k landmarks in view, plus O(k log k) to order them, and
// O(c Z) for c candidates to find twins; no allocation once the scratch has grown, beyond the maps'
// path copies.
#pragma once

#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "engine/association.h"
#include "engine/filter_config.h"
#include "engine/internal/scan_plan.h"
#include "engine/landmark_ekf.h"
#include "engine/measurement_model.h"
#include "engine/pose.h"
#include "memory/landmark_tree.h"
#include "memory/particle_map.h"
#include "memory/spatial_index.h"

namespace fastslam::engine::internal {

// The largest eigenvalue of a stored landmark's covariance, rounded up to a float: its spatial
// index entry's extent, which gates candidates before the map is read (candidate_search.h).
float largest_variance(const memory::Landmark& l);

// The map update's per-thread buffers.
struct MapUpdateScratch {
  std::vector<memory::Slot> touched;    // the chosen landmarks
  std::vector<std::uint32_t> observed;  // their observations
  std::vector<memory::SpatialEntry> in_view;
  // The landmarks the scan confirmed: chosen ones whose log-odds reached confirm_at, and new ones
  // that start at or above it.
  std::vector<memory::Slot> confirmed;
  std::vector<std::pair<std::uint32_t, memory::Slot>> twins;  // (observation, slot) to test
};

// What the map update reads besides the particle.
struct MapUpdateInput {
  const RangeBearingModel* sensor = nullptr;
  Eigen::Matrix2d r;
  ExistenceConfig existence;
  double max_range = 0.0;
  double field_of_view = 0.0;
  std::uint64_t scan_step = 0;
  double merge_gate = 0.0;  // LoopClosureConfig::merge_gate; 0: twins are never merged
  // ln(1 - P_D) under data association sampling with a detection model (P_D < 1, false
  // alarms): the likelihood factor of each confirmed landmark in the footprint that the scan's
  // draw left undetected, which the draw's normalisers leave out. 0: none.
  double log_missed = 0.0;
};

// Landmarks the update started and removed (by negative information, or merged into a twin).
struct MapUpdateCounts {
  std::uint64_t created = 0;
  std::uint64_t removed = 0;
};

// One particle's map update. assignment[j]: observation j's slot or kNewLandmark. FastSLAM 1.0
// (kFs2 false) reuses the association's EKF terms, terms[chosen_terms[j]] (same pose, same
// landmark, since no other observation takes it); 2.0 evaluates them at the drawn `pose`.
// Returns the particle's log-weight factor of its missed detections: in.log_missed times the
// confirmed landmarks in the footprint that no observation took (0 when in.log_missed is 0).
template <bool kFs2>
double update_particle_map(const MapUpdateInput& in, const Pose& pose,
                           const std::vector<PlannedObservation>& scan,
                           std::span<const std::int64_t> assignment,
                           std::span<const LandmarkObservation> terms,
                           std::span<const std::uint32_t> chosen_terms, memory::ParticleMap& map,
                           MapUpdateScratch& scratch, MapUpdateCounts& counts,
                           std::span<const AssociationCandidate> candidates = {});

extern template double update_particle_map<false>(
    const MapUpdateInput&, const Pose&, const std::vector<PlannedObservation>&,
    std::span<const std::int64_t>, std::span<const LandmarkObservation>,
    std::span<const std::uint32_t>, memory::ParticleMap&, MapUpdateScratch&, MapUpdateCounts&,
    std::span<const AssociationCandidate>);
extern template double update_particle_map<true>(
    const MapUpdateInput&, const Pose&, const std::vector<PlannedObservation>&,
    std::span<const std::int64_t>, std::span<const LandmarkObservation>,
    std::span<const std::uint32_t>, memory::ParticleMap&, MapUpdateScratch&, MapUpdateCounts&,
    std::span<const AssociationCandidate>);

}  // namespace fastslam::engine::internal
