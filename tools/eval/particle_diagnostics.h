// Diagnostics of the particle set for telling the ways a filter fails apart: particle depletion
// (few distinct particles, a low N_eff), a proposal that misses (the truth many spreads from the
// mean while the set is tight), or a wrong association (the particle nearest the truth weighted
// down). Computed from the particles' positions and log-weights, against a truth position.
//
// Ownership: spans borrowed for the call. Thread safety: pure function.
// Costs: O(M log M) for M particles (the distinct count sorts the positions); allocates O(M).
#pragma once

#include <cstddef>
#include <optional>
#include <span>

#include "tools/io/tum.h"

namespace fastslam::tools {

struct ParticleDiagnostics {
  double effective_sample_size = 0.0;  // 1 / sum w^2 of the normalised weights
  std::size_t distinct = 0;            // distinct positions: after resampling, the survivors
  double spread = 0.0;                 // m, weighted RMS distance of the positions from the mean
  // With a truth position: its distance from the weighted mean in spreads (none when the
  // spread is 0), and M x the normalised weight of the particle nearest it (1: an average
  // particle's weight; near 0: the filter is weighting down the hypothesis closest to the truth).
  std::optional<double> truth_spreads;
  std::optional<double> nearest_weight;
};

// REQUIRES: x, y and log_weight of one size M >= 1, finite positions, log-weights not all -inf.
// Throws std::invalid_argument otherwise.
ParticleDiagnostics diagnose_particles(std::span<const double> x, std::span<const double> y,
                                       std::span<const double> log_weight,
                                       const std::optional<StampedPose>& truth);

}  // namespace fastslam::tools
