#include "engine/internal/map_update.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include <Eigen/LU>

#include "engine/association.h"

namespace fastslam::engine::internal {
namespace {

// The chosen landmarks updated and their index entries moved (one run of moves: they lie near
// each other); their slots go to `touched`, their observations to `observed`.
template <bool kFs2>
void update_chosen(const MapUpdateInput& in, const Pose& pose,
                   const std::vector<PlannedObservation>& scan,
                   std::span<const std::int64_t> assignment,
                   std::span<const LandmarkObservation> terms,
                   std::span<const std::uint32_t> chosen_terms, memory::ParticleMap& map,
                   std::vector<memory::Slot>& touched, std::vector<std::uint32_t>& observed,
                   std::vector<memory::Slot>& confirmed) {
  const auto step_now = static_cast<std::int64_t>(in.scan_step);
  touched.clear();
  observed.clear();
  confirmed.clear();
  for (std::size_t j = 0; j < scan.size(); ++j) {
    if (assignment[j] == kNewLandmark) continue;
    touched.push_back(static_cast<memory::Slot>(assignment[j]));
    observed.push_back(static_cast<std::uint32_t>(j));
  }
  map.update_each(
      touched,
      [&](std::size_t k, memory::Landmark& stored) {
        const std::size_t j = observed[k];
        LandmarkGaussian lm = to_gaussian(stored);
        if constexpr (kFs2) {
          apply_update(lm, evaluate_observation(*in.sensor, lm, pose, scan[j].z, in.r), in.r);
        } else {
          apply_update(lm, terms[chosen_terms[j]], in.r);
        }
        store_gaussian(lm, stored);
        const bool provisional = !(stored.log_odds >= in.existence.confirm_at);
        stored.log_odds += in.existence.seen;
        if (provisional && stored.log_odds >= in.existence.confirm_at) {
          confirmed.push_back(touched[k]);
        }
        stored.last_seen = step_now;
      },
      largest_variance);
}

// The landmarks in the footprint that the scan did not touch, into scratch.in_view in slot order
// (independent of the index's leaf order).
void collect_in_view(const MapUpdateInput& in, const Pose& pose, const memory::ParticleMap& map,
                     MapUpdateScratch& scratch) {
  const Eigen::Vector2d at = in.sensor->sensor_position(pose);
  scratch.in_view.clear();
  map.index().in_footprint(at[0], at[1], pose[2] + in.sensor->offset().yaw,
                           in.max_range - in.existence.range_margin, in.field_of_view,
                           [&](const memory::SpatialEntry& e) {
                             if (std::find(scratch.touched.begin(), scratch.touched.end(),
                                           e.slot) == scratch.touched.end()) {
                               scratch.in_view.push_back(e);
                             }
                           });
  std::sort(
      scratch.in_view.begin(), scratch.in_view.end(),
      [](const memory::SpatialEntry& a, const memory::SpatialEntry& b) { return a.slot < b.slot; });
}

// The landmarks of scratch.in_view, each missed by this scan, in slot order: with negative
// information each loses `missed` log-odds and is removed below the bound. Returns how many of
// them were confirmed before (sampling's missed detections).
std::size_t miss_in_view(const MapUpdateInput& in, memory::ParticleMap& map,
                         const MapUpdateScratch& scratch, MapUpdateCounts& counts) {
  const ExistenceConfig& ex = in.existence;
  std::size_t confirmed = 0;
  for (const memory::SpatialEntry& e : scratch.in_view) {
    const double before = map.at(e.slot).log_odds;
    if (before >= ex.confirm_at) ++confirmed;
    if (!ex.negative_information) continue;
    const double log_odds = before - ex.missed;
    if (log_odds < ex.remove_below) {
      map.erase(e.slot);
      ++counts.removed;
    } else {
      map.update(
          e.slot, [&](memory::Landmark& stored) { stored.log_odds = log_odds; }, largest_variance);
    }
  }
  return confirmed;
}

// Twins (filter_config.h LoopClosureConfig::merge_gate): a chosen landmark and another confirmed
// candidate of its observation that no observation took, whose means lie within the gate of each
// other under their two covariances (the test that two estimates are of one point; the sensor's
// noise is left out, or a noisy sensor would join distinct landmarks a metre or two apart, as
// Victoria Park's trees). The other goes; the chosen one keeps its slot and id (the scan's
// report names them) and takes the larger log-odds and the better-known estimate after this
// observation: its own as updated, or the other's updated now by the same observation, whichever
// covariance has the smaller determinant (a restarted copy must not replace a landmark seen a
// hundred times). In (observation, slot) order, so that the result does not depend on the order
// of the index's leaves.
void merge_twins(const MapUpdateInput& in, const Pose& pose,
                 const std::vector<PlannedObservation>& scan,
                 std::span<const std::int64_t> assignment,
                 std::span<const AssociationCandidate> candidates, memory::ParticleMap& map,
                 MapUpdateScratch& scratch, MapUpdateCounts& counts) {
  std::vector<std::pair<std::uint32_t, memory::Slot>>& twins = scratch.twins;
  twins.clear();
  for (const AssociationCandidate& c : candidates) {
    const std::int64_t chosen = assignment[c.observation];
    if (chosen == kNewLandmark || chosen == static_cast<std::int64_t>(c.slot)) continue;
    if (std::find(assignment.begin(), assignment.end(), static_cast<std::int64_t>(c.slot)) !=
        assignment.end()) {
      continue;  // another observation's landmark: not the same one
    }
    twins.emplace_back(c.observation, c.slot);
  }
  if (twins.empty()) return;
  std::sort(twins.begin(), twins.end());
  const double confirm_at = in.existence.confirm_at;
  for (const auto& [j, slot] : twins) {
    const auto keep = static_cast<memory::Slot>(assignment[j]);
    const memory::Landmark* mine = map.find(keep);
    const memory::Landmark* other = map.find(slot);
    if (mine == nullptr || other == nullptr) continue;  // erased by an earlier merge
    if (!(mine->log_odds >= confirm_at) || !(other->log_odds >= confirm_at)) continue;
    const LandmarkGaussian a = to_gaussian(*mine);
    const LandmarkGaussian b = to_gaussian(*other);
    const Eigen::Vector2d d = a.mean - b.mean;
    if (!(d.dot((a.cov + b.cov).inverse() * d) <= in.merge_gate)) continue;
    LandmarkGaussian theirs = b;
    apply_update(theirs, evaluate_observation(*in.sensor, theirs, pose, scan[j].z, in.r), in.r);
    const bool take_theirs = theirs.cov.determinant() < a.cov.determinant();
    const double log_odds = std::max(mine->log_odds, other->log_odds);
    map.erase(slot);
    map.update(
        keep,
        [&](memory::Landmark& stored) {
          if (take_theirs) store_gaussian(theirs, stored);
          stored.log_odds = log_odds;
        },
        largest_variance);
    std::erase(scratch.confirmed, slot);
    ++counts.removed;
  }
}

}  // namespace

float largest_variance(const memory::Landmark& l) {
  const double half_gap = 0.5 * (l.sxx - l.syy);
  const double v = 0.5 * (l.sxx + l.syy) + std::sqrt(half_gap * half_gap + l.sxy * l.sxy);
  const auto f = static_cast<float>(v);
  return static_cast<double>(f) >= v ? f
                                     : std::nextafter(f, std::numeric_limits<float>::infinity());
}

template <bool kFs2>
double update_particle_map(const MapUpdateInput& in, const Pose& pose,
                           const std::vector<PlannedObservation>& scan,
                           std::span<const std::int64_t> assignment,
                           std::span<const LandmarkObservation> terms,
                           std::span<const std::uint32_t> chosen_terms, memory::ParticleMap& map,
                           MapUpdateScratch& scratch, MapUpdateCounts& counts,
                           std::span<const AssociationCandidate> candidates) {
  update_chosen<kFs2>(in, pose, scan, assignment, terms, chosen_terms, map, scratch.touched,
                      scratch.observed, scratch.confirmed);
  if (in.merge_gate > 0.0) {
    merge_twins(in, pose, scan, assignment, candidates, map, scratch, counts);
  }
  const ExistenceConfig& ex = in.existence;
  double log_weight = 0.0;
  if ((ex.negative_information || in.log_missed != 0.0) && in.max_range > ex.range_margin) {
    collect_in_view(in, pose, map, scratch);
    const std::size_t missed = miss_in_view(in, map, scratch, counts);
    if (in.log_missed != 0.0) log_weight = static_cast<double>(missed) * in.log_missed;
  }
  const auto step_now = static_cast<std::int64_t>(in.scan_step);
  for (std::size_t j = 0; j < scan.size(); ++j) {
    if (assignment[j] != kNewLandmark) continue;
    memory::Landmark stored;
    store_gaussian(initialize_landmark(*in.sensor, pose, scan[j].z, in.r), stored);
    stored.log_odds = ex.initial;
    stored.id = in.scan_step * kLandmarkIdsPerScan + j;
    stored.last_seen = step_now;
    const memory::Slot slot = map.insert(stored, largest_variance(stored));
    if (stored.log_odds >= ex.confirm_at) scratch.confirmed.push_back(slot);
    ++counts.created;
  }
  return log_weight;
}

template double update_particle_map<false>(const MapUpdateInput&, const Pose&,
                                           const std::vector<PlannedObservation>&,
                                           std::span<const std::int64_t>,
                                           std::span<const LandmarkObservation>,
                                           std::span<const std::uint32_t>, memory::ParticleMap&,
                                           MapUpdateScratch&, MapUpdateCounts&,
                                           std::span<const AssociationCandidate>);
template double update_particle_map<true>(const MapUpdateInput&, const Pose&,
                                          const std::vector<PlannedObservation>&,
                                          std::span<const std::int64_t>,
                                          std::span<const LandmarkObservation>,
                                          std::span<const std::uint32_t>, memory::ParticleMap&,
                                          MapUpdateScratch&, MapUpdateCounts&,
                                          std::span<const AssociationCandidate>);

}  // namespace fastslam::engine::internal
