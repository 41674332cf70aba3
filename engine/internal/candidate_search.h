// The candidate search of unknown association, for one particle and one scan: which landmarks of
// the particle's map each observation may be of, with their log-likelihoods, gated. Each
// observation's candidates come from a disc around the landmark position it implies (radius from
// the Mahalanobis gate: Mahalanobis^2 >= |d|^2 / lambda_max(Sigma + R_xy + pose term) under
// linearisation, and a landmark's covariance never exceeds its initial one, whose largest
// eigenvalue `variance_bound` bounds), so the map is never scanned. All the scan's discs descend
// the spatial index together from the node covering them; entries whose own extent (largest
// covariance eigenvalue) cannot reach are skipped in the index, and (FastSLAM 1.0) so are those
// whose Mahalanobis distance provably exceeds the limit (range_bearing_mahalanobis2_bound), before
// the map lookup. Maximum likelihood never takes a candidate below ln p0, so those are not kept;
// since det Q >= det R, neither is one whose m^2 exceeds 2 (-ln 2 pi - ln det R / 2 - ln p0).
// FastSLAM 2.0 scores candidates with the pose integrated out (eq. 60-61); 1.0 keeps each
// candidate's EKF terms (tag = index into `terms`) for the update.
// Thread safety: reads the map and index; concurrent calls with distinct scratch are safe.
// Costs: O(h + k) index work and O(c) exact gates for k entries reached and c near enough; no
// allocation once the scratch has grown.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include <Eigen/Core>

#include "engine/association.h"
#include "engine/internal/scan_plan.h"
#include "engine/landmark_ekf.h"
#include "engine/measurement_model.h"
#include "engine/pose.h"
#include "engine/proposal.h"
#include "memory/landmark_tree.h"
#include "memory/spatial_index.h"

namespace fastslam::engine::internal {

// The candidate search's per-thread buffers and its results.
struct CandidateScratch {
  std::vector<AssociationCandidate> candidates;  // the result; 1.0: tag = index into `terms`
  std::vector<LandmarkObservation> terms;        // 1.0: each candidate's EKF terms
  // Observation j's disc: x, y, radius, and the part of the spread that is not the landmark's
  // own (measurement, and for 2.0 the pose).
  std::vector<std::array<double, 4>> discs;
  std::vector<memory::SpatialIndex::Disc> queries;  // the discs as the index takes them
  std::vector<Eigen::Vector2d> directions;          // observation j's bearing in the world
};

// What the search reads besides the particle.
struct SearchInput {
  const RangeBearingModel* sensor = nullptr;
  Eigen::Matrix2d r;
  double gate = 0.0;          // Mahalanobis^2 gate
  double search_scale = 1.0;  // disc radius factor
  // ln p0, the likelihood of a new landmark; with a detection model every observation's "no
  // landmark" score is at least this (association.h), so the cut below stays safe.
  double log_p0 = 0.0;
  double variance_bound = 0.0;
};

namespace candidate_search_detail {

// The scan's discs (scratch.discs) around pose `pose`; returns the bounding box of them all
// (min x, min y, max x, max y).
template <int N, bool kFs2>
std::array<double, 4> plan_discs(const SearchInput& in, const Pose& pose,
                                 const PoseGaussian<N>& prior,
                                 const std::vector<PlannedObservation>& scan,
                                 CandidateScratch& scratch) {
  const RangeBearingModel& sensor = *in.sensor;
  const double offset = std::hypot(sensor.offset().x, sensor.offset().y);
  const double scale2 = in.search_scale * in.search_scale;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  std::array<double, 4> box = {kInf, kInf, -kInf, -kInf};
  scratch.discs.resize(scan.size());
  for (std::size_t j = 0; j < scan.size(); ++j) {
    const Eigen::Vector2d& z = scan[j].z;
    const Eigen::Vector2d at = sensor.landmark_from(z, pose);
    double spread = measurement_variance(in.r, z[0]);
    if constexpr (kFs2) {
      const double lever = z[0] + offset;
      spread += 2.0 * (prior.cov(0, 0) + prior.cov(1, 1)) + 2.0 * lever * lever * prior.cov(2, 2);
    }
    const double radius = std::sqrt(scale2 * in.gate * (in.variance_bound + spread));
    scratch.discs[j] = {at[0], at[1], radius, spread};
    box[0] = std::min(box[0], at[0] - radius);
    box[1] = std::min(box[1], at[1] - radius);
    box[2] = std::max(box[2], at[0] + radius);
    box[3] = std::max(box[3], at[1] + radius);
  }
  return box;
}

}  // namespace candidate_search_detail

// Fills scratch.candidates (and, for 1.0, scratch.terms) for `scan` against the particle's map
// and index. `prior` is the particle's state (2.0: with its predicted covariance); its first
// three components are the pose the observations are taken from.
template <int N, bool kFs2, bool kMl>
void find_candidates(const SearchInput& in, const PoseGaussian<N>& prior,
                     const memory::LandmarkTree& map, const memory::SpatialIndex& index,
                     const std::vector<PlannedObservation>& scan, CandidateScratch& scratch) {
  const RangeBearingModel& sensor = *in.sensor;
  const Pose pose = prior.mean.template head<3>();  // 1.0: the sampled pose; 2.0: the mean
  const Eigen::Vector2d from = sensor.sensor_position(pose);
  scratch.candidates.clear();
  scratch.terms.clear();
  const std::array<double, 4> box =
      candidate_search_detail::plan_discs<N, kFs2>(in, pose, prior, scan, scratch);
  // A margin of 1/64 of the box's extent, so that rounding near the edges rarely sends a
  // query back to the root (within() checks the containment exactly either way).
  const double pad = 0.015625 * (box[2] - box[0] + box[3] - box[1]);
  const memory::SpatialIndex::Subtree near =
      scan.empty() || !std::isfinite(pad)
          ? memory::SpatialIndex::Subtree()
          : index.covering(box[0] - pad, box[1] - pad, box[2] + pad, box[3] + pad);
  const double gate = in.gate;
  const double log_p0 = in.log_p0;
  double limit = gate;
  if constexpr (kMl) {
    const double log_det_r = std::log(in.r(0, 0) * in.r(1, 1) - in.r(0, 1) * in.r(1, 0));
    limit = std::min(limit, 2.0 * (-kLogTwoPi - 0.5 * log_det_r - log_p0));
  }
  // The margin lies far above the bound's rounding and that of ln det.
  const double bound_limit = limit + 1e-6 * (std::fabs(limit) + 1.0);
  // The observed directions (unit, to rounding): at = sensor position + z_r (cos, sin).
  scratch.queries.resize(scan.size());
  scratch.directions.resize(scan.size());
  for (std::size_t j = 0; j < scan.size(); ++j) {
    const auto [at_x, at_y, radius, spread] = scratch.discs[j];
    scratch.queries[j] = {at_x, at_y, radius};
    scratch.directions[j] = {(at_x - from[0]) / scan[j].z[0], (at_y - from[1]) / scan[j].z[0]};
  }
  const double scale2 = in.search_scale * in.search_scale;
  const auto reach2 = [&](std::size_t j, float extent) {
    return scale2 * gate * (static_cast<double>(extent) + scratch.discs[j][3]);
  };
  index.within_reach(
      near, scratch.queries, reach2, [&](std::size_t j, const memory::SpatialEntry& e) {
        const Eigen::Vector2d& z = scan[j].z;
        if ((Eigen::Vector2d(e.x, e.y) - from).squaredNorm() < 1e-18) return;  // g undefined
        if constexpr (!kFs2) {
          if (range_bearing_mahalanobis2_bound(from, scratch.directions[j], z[0], e.x, e.y,
                                               static_cast<double>(e.extent), in.r) > bound_limit) {
            return;
          }
        }
        const LandmarkGaussian lm = to_gaussian(map.at(e.slot));
        const auto obs = static_cast<std::uint32_t>(j);
        if constexpr (kFs2) {
          const ProposalObservation<N> t = evaluate_proposal<N>(sensor, lm, prior, z, in.r);
          if (t.mahalanobis2 <= gate && !(kMl && t.log_likelihood < log_p0)) {
            scratch.candidates.push_back(
                {obs, e.slot, t.log_likelihood, 0, static_cast<float>(t.mahalanobis2)});
          }
        } else {
          const LandmarkObservation t = evaluate_observation(sensor, lm, pose, z, in.r);
          if (t.mahalanobis2 <= gate && !(kMl && t.log_likelihood < log_p0)) {
            const auto tag = static_cast<std::uint32_t>(scratch.terms.size());
            scratch.terms.push_back(t);
            scratch.candidates.push_back(
                {obs, e.slot, t.log_likelihood, tag, static_cast<float>(t.mahalanobis2)});
          }
        }
      });
}

}  // namespace fastslam::engine::internal
