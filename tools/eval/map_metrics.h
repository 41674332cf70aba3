// Set distances between an estimated map and the true landmarks when the estimate's ids mean
// nothing: GOSPA (Rahmathullah, Garcia-Fernandez, Svensson, "Generalized optimal sub-pattern
// assignment metric", FUSION 2017) with alpha = 2 and its decomposition, OSPA (Schuhmacher, Vo,
// Vo 2008), and precision and recall at a match radius. Definitions: docs/evaluation.md.
//
// With alpha = 2, pairing two points costs min(d, c)^p and leaving both out c^p / 2 + c^p / 2,
// so only pairs closer than c are worth pairing: the optimal assignment is a min-cost matching
// on the sparse graph of such pairs (found with the truth kd-tree), solved exactly (Hungarian)
// on each connected component. OSPA with the same c and p minimises the same sum over the same
// pairs (sum of d^p - c^p), so it shares the assignment.
//
// Ownership: spans and the index are borrowed for the call. Thread safety: pure functions.
// Costs: O(E log T) radius queries plus O(k1^2 k2) per component of k1 <= k2 points, O(k1 k2)
// memory. A component larger than max_exact_component points (a cutoff wider than the landmark
// spacing chains everything together) is paired greedily, nearest pairs first, in
// O(P log P) for its P pairs instead: the result is then an upper bound, and counted.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "engine/filter.h"
#include "tools/sim/world.h"

namespace fastslam::tools {

struct GospaOptions {
  double cutoff = 1.0;  // c, m; finite, > 0
  double order = 2.0;   // p; finite, >= 1
  // Points (estimated + true) of a component solved exactly; larger ones greedily.
  std::size_t max_exact_component = 2000;
};

struct Gospa {
  // distance^p = localisation + cutoff^p / 2 * (missed + false_targets).
  double distance = 0.0;      // m
  double localisation = 0.0;  // m^p: sum of d^p over the assigned pairs
  std::size_t assigned = 0;
  std::size_t missed = 0;         // true landmarks left unassigned
  std::size_t false_targets = 0;  // estimated landmarks left unassigned
  // ((localisation + cutoff^p (n - assigned)) / n)^(1/p), n = the larger set's size; 0 when
  // both sets are empty.
  double ospa = 0.0;                   // m
  std::size_t components = 0;          // of the graph of pairs closer than the cutoff
  std::size_t largest_component = 0;   // points
  std::size_t inexact_components = 0;  // paired greedily (see the file comment)
};

// `observed[i]` says whether true landmark i counts (empty: every one): the others are neither
// missed nor assignable. REQUIRES: truth_index indexes `truth`. Throws std::invalid_argument on
// bad options or an `observed` of the wrong size.
Gospa gospa(std::span<const Point> estimate, const std::vector<Point>& truth,
            const TruthIndex& truth_index, std::span<const bool> observed,
            const GospaOptions& options);

// Precision = matched / estimated, recall = matched / true (1 for an empty set), from a
// maximum-cardinality matching of pairs closer than match_radius, the least sum of squared
// distances among those (exact per component, as gospa(), greedy past max_exact_component).
struct Detection {
  std::size_t matched = 0;
  double precision = 1.0;
  double recall = 1.0;
  std::size_t inexact_components = 0;
};
Detection precision_recall(std::span<const Point> estimate, const std::vector<Point>& truth,
                           const TruthIndex& truth_index, std::span<const bool> observed,
                           double match_radius, std::size_t max_exact_component = 2000);

// The positions of a map, for the functions above. O(N), allocates.
std::vector<Point> positions(std::span<const engine::MapLandmark> map);

}  // namespace fastslam::tools
