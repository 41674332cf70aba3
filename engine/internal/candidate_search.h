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
// FastSLAM 1.0 under maximum likelihood defers the exact terms: the search keeps each candidate
// that passes the bounds with an upper bound on its ln p (tag kBoundOnly, lazy_association.h),
// from the same two bounds (m^2 >= the Mahalanobis bound, det Q >= det R), and
// `choose_maximum_likelihood` evaluates only those the greedy choice or the scan report needs;
// most candidates of a dense patch cannot win and are never evaluated. When no landmark is a
// candidate of two observations the choice is made per observation (no joint order to keep).
// The discs' centres take one sine and cosine per particle when the pass gives the scan's
// bearings (scan_bearings, once per scan for every particle).
// Thread safety: reads the map and index; concurrent calls with distinct scratch are safe.
// Costs: O(h + k) index work and O(c) exact gates for k entries reached and c near enough (1.0
// ML: the c evaluated by the choice); no allocation once the scratch has grown.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <type_traits>
#include <vector>

#include <Eigen/Core>

#include "engine/association.h"
#include "engine/internal/lazy_association.h"
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
  std::vector<std::uint32_t> counts;                // 1.0 ML: candidates of observation j
  LazyScratch lazy;                                 // 1.0 ML: the choice's
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
  // Observation j's bearing as (cos, sin), the same in every particle (scan_bearings): the
  // discs' centres then take one sine and cosine per particle, not one per observation. Empty:
  // each centre from RangeBearingModel::landmark_from.
  std::span<const Eigen::Vector2d> bearings;
  // FastSLAM 2.0: candidates scored under L + (scale - 1) R (proposal.h weight_scale).
  double weight_scale = 1.0;
};

// The scan's bearings as SearchInput::bearings takes them, into `out`.
inline void scan_bearings(const std::vector<PlannedObservation>& scan,
                          std::vector<Eigen::Vector2d>& out) {
  out.resize(scan.size());
  for (std::size_t j = 0; j < scan.size(); ++j) {
    out[j] = {std::cos(scan[j].z[1]), std::sin(scan[j].z[1])};
  }
}

namespace candidate_search_detail {

// FastSLAM 1.0's exact terms of candidate `c` (observation c.observation, landmark c.slot) seen
// from `pose`: appends them to `terms` and fills c's log-likelihood, tag and distance; false,
// appending nothing, when the exact gate (or, under ML, the ln p0 floor) rejects it.
template <bool kMl>
bool evaluate_candidate(const SearchInput& in, const Pose& pose, const memory::LandmarkTree& map,
                        const std::vector<PlannedObservation>& scan, AssociationCandidate& c,
                        std::vector<LandmarkObservation>& terms) {
  const LandmarkGaussian lm = to_gaussian(map.at(c.slot));
  const LandmarkObservation t =
      evaluate_observation(*in.sensor, lm, pose, scan[c.observation].z, in.r);
  if (!(t.mahalanobis2 <= in.gate) || (kMl && t.log_likelihood < in.log_p0)) return false;
  c.log_likelihood = t.log_likelihood;
  c.tag = static_cast<std::uint32_t>(terms.size());
  c.mahalanobis2 = static_cast<float>(t.mahalanobis2);
  terms.push_back(t);
  return true;
}

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
  // The sensor's heading, rotated by each bearing (angle addition, to rounding the same point
  // as landmark_from: the disc is a search region, the exact terms never read it).
  const bool rotate = in.bearings.size() == scan.size();
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();
  double cos_heading = 1.0;
  double sin_heading = 0.0;
  if (rotate) {
    origin = sensor.sensor_position(pose);
    const double heading = pose[2] + sensor.offset().yaw;
    cos_heading = std::cos(heading);
    sin_heading = std::sin(heading);
  }
  for (std::size_t j = 0; j < scan.size(); ++j) {
    const Eigen::Vector2d& z = scan[j].z;
    Eigen::Vector2d at;
    if (rotate) {
      const Eigen::Vector2d& b = in.bearings[j];
      at = origin + z[0] * Eigen::Vector2d(cos_heading * b[0] - sin_heading * b[1],
                                           sin_heading * b[0] + cos_heading * b[1]);
    } else {
      at = sensor.landmark_from(z, pose);
    }
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
// three components are the pose the observations are taken from. FastSLAM 1.0 under maximum
// likelihood: the candidates carry bounds (tag kBoundOnly) and scratch.terms stays empty until
// choose_maximum_likelihood (or evaluate_all) evaluates them.
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
  double log_peak = 0.0;  // the largest ln p any candidate can have: -ln 2 pi - ln det R / 2
  if constexpr (kMl) {
    const double log_det_r = std::log(in.r(0, 0) * in.r(1, 1) - in.r(0, 1) * in.r(1, 0));
    log_peak = -kLogTwoPi - 0.5 * log_det_r;
    limit = std::min(limit, 2.0 * (log_peak - log_p0));
  }
  // The margin lies far above the bound's rounding and that of ln det.
  const double bound_limit = limit + 1e-6 * (std::fabs(limit) + 1.0);
  // The observed directions (unit, to rounding): at = sensor position + z_r (cos, sin).
  scratch.queries.resize(scan.size());
  scratch.directions.resize(scan.size());
  if constexpr (kMl && !kFs2) scratch.counts.assign(scan.size(), 0);
  for (std::size_t j = 0; j < scan.size(); ++j) {
    const auto [at_x, at_y, radius, spread] = scratch.discs[j];
    scratch.queries[j] = {at_x, at_y, radius};
    scratch.directions[j] = {(at_x - from[0]) / scan[j].z[0], (at_y - from[1]) / scan[j].z[0]};
  }
  // By value: the visits below write to the scratch, so a reference would be reloaded per
  // entry. The product is the same as scale2 * gate * (...), which multiplies left to right.
  const double reach_scale = in.search_scale * in.search_scale * gate;
  const std::array<double, 4>* const discs = scratch.discs.data();
  const auto reach2 = [reach_scale, discs](std::size_t j, float extent) {
    return reach_scale * (static_cast<double>(extent) + discs[j][3]);
  };
  index.within_reach(
      near, scratch.queries, reach2, [&](std::size_t j, const memory::SpatialEntry& e) {
        const Eigen::Vector2d& z = scan[j].z;
        const auto obs = static_cast<std::uint32_t>(j);
        double bound = 0.0;
        if constexpr (!kFs2) {
          bound = range_bearing_mahalanobis2_bound(from, scratch.directions[j], z[0], e.x, e.y,
                                                   static_cast<double>(e.extent), in.r);
          if (bound > bound_limit) return;
        }
        if ((Eigen::Vector2d(e.x, e.y) - from).squaredNorm() < 1e-18) return;  // g undefined
        if constexpr (!kFs2 && kMl) {
          // ln p = -ln 2 pi - ln det Q / 2 - m^2 / 2 <= log_peak - bound / 2, with a margin far
          // above the rounding of either side (no bound, +inf, from a NaN extent).
          const double high = log_peak - 0.5 * bound;
          const double key = high + 1e-6 * (std::fabs(high) + bound + 1.0);
          constexpr double kNoBound = std::numeric_limits<double>::infinity();
          scratch.candidates.push_back(
              {obs, e.slot, std::isnan(key) ? kNoBound : key, kBoundOnly, 0.0f});
          ++scratch.counts[j];
          return;
        }
        if constexpr (kFs2) {
          const LandmarkGaussian lm = to_gaussian(map.at(e.slot));
          ProposalObservation<N> t = evaluate_proposal<N>(sensor, lm, prior, z, in.r);
          if (in.weight_scale != 1.0) scale_weight<N>(t, in.r, in.weight_scale);
          if (t.mahalanobis2 <= gate && !(kMl && t.log_likelihood < log_p0)) {
            scratch.candidates.push_back(
                {obs, e.slot, t.log_likelihood, 0, static_cast<float>(t.mahalanobis2)});
          }
        } else {
          AssociationCandidate c{obs, e.slot, 0.0, 0, 0.0f};
          if (candidate_search_detail::evaluate_candidate<kMl>(in, pose, map, scan, c,
                                                               scratch.terms)) {
            scratch.candidates.push_back(c);
          }
        }
      });
}

namespace candidate_search_detail {

// choose_maximum_likelihood's body: `Unassociated` as association.h's overloads take it.
template <int N, class Unassociated>
double choose(const SearchInput& in, const PoseGaussian<N>& prior, const memory::LandmarkTree& map,
              const std::vector<PlannedObservation>& scan, CandidateScratch& scratch,
              const Unassociated& log_unassociated, std::span<std::int64_t> assignment) {
  const Pose pose = prior.mean.template head<3>();
  const auto evaluate = [&](AssociationCandidate& c) {
    return evaluate_candidate<true>(in, pose, map, scan, c, scratch.terms);
  };
  // When no observation has more than one candidate, each is needed whatever the others do
  // (it is taken, or its observation ends new and the report reads its distance): all are
  // evaluated, and the plain sort is cheaper than the lazy choice.
  std::vector<AssociationCandidate>& candidates = scratch.candidates;
  if (std::all_of(scratch.counts.begin(), scratch.counts.end(),
                  [](std::uint32_t n) { return n <= 1; })) {
    std::size_t kept = 0;
    for (AssociationCandidate& c : candidates) {
      if (evaluate(c)) candidates[kept++] = c;
    }
    candidates.resize(kept);
    return associate_maximum_likelihood(candidates, log_unassociated, assignment);
  }
  // When no landmark is a candidate of two observations (the usual case once gated), the
  // choice is made per observation; the check is quadratic, so long lists go to the joint one.
  const bool independent = candidates.size() <= 16 && slots_disjoint(candidates);
  if constexpr (std::is_same_v<Unassociated, double>) {
    const auto score = [log_unassociated](std::size_t) { return log_unassociated; };
    return independent ? independent_maximum_likelihood(candidates, score, true, assignment,
                                                        scratch.lazy, evaluate)
                       : lazy_maximum_likelihood(candidates, score, true, assignment, scratch.lazy,
                                                 evaluate);
  } else {
    const auto score = [log_unassociated](std::size_t j) { return log_unassociated[j]; };
    return independent ? independent_maximum_likelihood(candidates, score, false, assignment,
                                                        scratch.lazy, evaluate)
                       : lazy_maximum_likelihood(candidates, score, false, assignment, scratch.lazy,
                                                 evaluate);
  }
}

}  // namespace candidate_search_detail

// FastSLAM 1.0, maximum likelihood: the choice of associate_maximum_likelihood over
// find_candidates<N, false, true>'s bounded candidates (same `in`, `prior`, map and scan),
// evaluating only those it needs (lazy_association.h). Leaves in scratch.candidates the exact
// candidates the scan report and the map update read (every candidate of an observation left
// new, the chosen pair of the others; tag = index into scratch.terms). Returns the log weight
// factor, bit-identical to associate_maximum_likelihood's on the fully evaluated list.
template <int N>
double choose_maximum_likelihood(const SearchInput& in, const PoseGaussian<N>& prior,
                                 const memory::LandmarkTree& map,
                                 const std::vector<PlannedObservation>& scan,
                                 CandidateScratch& scratch, double log_new_landmark,
                                 std::span<std::int64_t> assignment) {
  return candidate_search_detail::choose<N>(in, prior, map, scan, scratch, log_new_landmark,
                                            assignment);
}
// The same with observation j's "no landmark" scored log_unassociated[j] (association.h).
template <int N>
double choose_maximum_likelihood(const SearchInput& in, const PoseGaussian<N>& prior,
                                 const memory::LandmarkTree& map,
                                 const std::vector<PlannedObservation>& scan,
                                 CandidateScratch& scratch,
                                 std::span<const double> log_unassociated,
                                 std::span<std::int64_t> assignment) {
  return candidate_search_detail::choose<N>(in, prior, map, scan, scratch, log_unassociated,
                                            assignment);
}

// Evaluates every bounded candidate of find_candidates<N, false, true> (dropping those the exact
// gate or the ln p0 floor rejects): the list the eager search gave. For tests and tools.
template <int N>
void evaluate_all(const SearchInput& in, const PoseGaussian<N>& prior,
                  const memory::LandmarkTree& map, const std::vector<PlannedObservation>& scan,
                  CandidateScratch& scratch) {
  const Pose pose = prior.mean.template head<3>();
  std::size_t kept = 0;
  for (AssociationCandidate& c : scratch.candidates) {
    if (c.tag != kBoundOnly ||
        candidate_search_detail::evaluate_candidate<true>(in, pose, map, scan, c, scratch.terms)) {
      scratch.candidates[kept++] = c;
    }
  }
  scratch.candidates.resize(kept);
}

}  // namespace fastslam::engine::internal
