// Scoring an estimated map against true landmarks when the estimate's ids mean nothing (unknown
// data association): estimated and true landmarks are paired one to one, greedily by distance
// (nearest pairs first) within a match radius, found with the static kd-tree over the truth
// (tools/sim/world.h TruthIndex).
//   - rmse_m: RMS distance over the pairs;
//   - spurious: estimated landmarks with no partner (clutter, duplicates);
//   - missing: true landmarks the run observed (`observed`) with no partner.
//
// Ownership: spans borrowed for the call. Thread safety: pure function.
// Costs: O(E (log T + k) + P log P) for E estimated landmarks, T true ones, k true ones within
// the radius of each estimate and P candidate pairs.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "engine/filter.h"
#include "tools/sim/world.h"

namespace fastslam::tools {

struct MapScore {
  double rmse_m = 0.0;
  std::size_t matched = 0;
  std::size_t spurious = 0;
  std::size_t missing = 0;
};

// `observed[i]` says whether true landmark i was ever observed (empty: every one counts).
// Throws std::invalid_argument unless match_radius is finite and > 0 and `observed` is empty or
// has one flag per true landmark.
MapScore score_map(std::span<const engine::MapLandmark> estimate, const std::vector<Point>& truth,
                   const TruthIndex& truth_index, std::span<const bool> observed,
                   double match_radius);

}  // namespace fastslam::tools
