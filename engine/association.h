// Data association of one scan within one particle (paper section 6, eq. 62-67): which landmark
// each observation is of, or "new", with no two observations of the scan taking one landmark
// (mutual exclusion, end of section 6.5).
//
// Input: the gated candidates of the scan, (observation j, landmark slot, ln p_jn), where p_jn is
// the likelihood of eq. 67 (FastSLAM 2.0: eq. 61 with the pose integrated out), and ln p0, the
// likelihood of "a new landmark". Output: per observation, a slot or `kNewLandmark`, and the
// log importance-weight factor of the scan's association.
//   - Maximum likelihood (eq. 64), decided jointly: a greedy assignment over all candidate pairs
//     of the scan in decreasing likelihood (ties by observation, then slot), each pair taken
//     when both its observation and its landmark are still free and ln p >= ln p0; whatever is
//     left is new. Greedy is optimal whenever no two observations compete for a landmark (the
//     usual case once gated) and costs O(C log C) for C candidates; an optimal assignment
//     (Hungarian) would cost O(Z^3) per particle per scan for rarely a different answer.
//     Weight factor: sum over observations of ln p of the choice (ln p0 for new; table 1).
//   - Sampling (DAS, eq. 65): observations in scan order, each draws among its still-free
//     candidates and "new" with probability proportional to p_jn and p0, using one uniform
//     from the caller's stream per observation. Weight factor: sum over observations of
//     ln(p0 + sum of the free p_jn), the normaliser, which is the importance weight of a draw
//     from p_jn / normaliser (the chosen p alone would bias toward unlikely draws).
//
// With a detection model (filter_config.h DetectionConfig) "no landmark" is scored per
// observation: a new landmark or a false alarm, against a landmark that had to be detected,
// ln u_j = ln((p0 + kappa(z_j)) / P_D) (`log_unassociated`); the overloads taking a span use it
// in place of ln p0, in the choice and in the weight. The common factor P_D^Z of the scan is
// left out of every particle's weight alike. u_j >= p0, so a search cut at ln p0 stays valid.
//
// Ownership: spans borrowed for the call. Thread safety: pure functions (DAS advances the
// stream it is given). Costs: O(C (log C + Z)) for C candidates and Z observations, and O(Z)
// scratch in the caller's vector (no allocation once it has grown).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "engine/filter_config.h"
#include "memory/landmark_tree.h"
#include "parallel/random_stream.h"

namespace fastslam::engine {

struct AssociationCandidate {
  std::uint32_t observation = 0;
  memory::Slot slot = 0;
  double log_likelihood = 0.0;
  std::uint32_t tag = 0;  // the caller's (e.g. where it keeps this pair's terms); carried along
  float mahalanobis2 = 0.0f;  // the pair's squared distance, for reports; carried along
};

// `assignment` value of an observation that starts a new landmark.
inline constexpr std::int64_t kNewLandmark = -1;

// Maximum likelihood with mutual exclusion. Reorders `candidates`; writes assignment[j] for
// every j < assignment.size() (candidates must name observations below that). Returns the log
// weight factor.
double associate_maximum_likelihood(std::span<AssociationCandidate> candidates,
                                    double log_new_landmark, std::span<std::int64_t> assignment);
// The same with observation j's "no landmark" scored log_unassociated[j] (size: the
// observations).
double associate_maximum_likelihood(std::span<AssociationCandidate> candidates,
                                    std::span<const double> log_unassociated,
                                    std::span<std::int64_t> assignment);

// Data association sampling with mutual exclusion, drawing from `stream`. Reorders `candidates`;
// `taken` is scratch. Returns the log weight factor.
double associate_sampling(std::span<AssociationCandidate> candidates, double log_new_landmark,
                          parallel::RandomStream& stream, std::span<std::int64_t> assignment,
                          std::vector<memory::Slot>& taken);
// The same with observation j's "no landmark" scored log_unassociated[j].
double associate_sampling(std::span<AssociationCandidate> candidates,
                          std::span<const double> log_unassociated, parallel::RandomStream& stream,
                          std::span<std::int64_t> assignment, std::vector<memory::Slot>& taken);

// ln u = ln((p0 + clutter_density * range) / P_D): the score of "no landmark" for an
// observation at `range` (m). O(1).
double log_unassociated(double log_new_landmark, const DetectionConfig& detection, double range);

}  // namespace fastslam::engine
