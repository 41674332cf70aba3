// Maximum-likelihood association (association.h, associate_maximum_likelihood) over candidates
// of which some carry only an upper bound on their log-likelihood, evaluated exactly only when
// the choice or the scan report needs them. Most gated candidates cannot win: the greedy choice
// takes pairs in decreasing ln p, so a candidate whose bound lies below what its observation
// takes is never looked at, and one whose observation is already taken is dropped unevaluated.
//
// The result is that of associate_maximum_likelihood on the exactly evaluated candidate list:
// the same assignment and the same log weight (the same sum in the same order), and the
// candidates left in the vector are every candidate of the observations that end "new" (their
// nearest distance goes into the scan report) and the chosen pair of each other observation,
// all exact. Why: the candidates live in a max-heap ordered by (key, bound before exact, then
// observation and slot as the eager sort), the key being the exact ln p or the bound. When an
// exact candidate is on top, every bounded one below has a bound, hence an exact ln p, strictly
// smaller (an equal bound sorts first and is evaluated first), so the top is the next pair of
// the eager order; a bounded candidate on top is evaluated and goes back in (or is dropped when
// `evaluate` rejects it, as the eager search would not have kept it).
//
// `evaluate(c)`: given a candidate with tag == kBoundOnly, fills its exact log_likelihood, tag
// and mahalanobis2 and returns true, or returns false when the exact candidate is not kept.
// REQUIRES: a bounded candidate's log_likelihood >= its exact one; tags other than kBoundOnly
// for exact candidates. Thread safety: a pure function of its arguments and `evaluate`. Costs:
// O((C + E) log C) for C candidates and E evaluations, no allocation (the heap is the vector).
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "engine/association.h"

namespace fastslam::engine::internal {

// The tag of a candidate whose log_likelihood is an upper bound, not yet evaluated.
inline constexpr std::uint32_t kBoundOnly = std::numeric_limits<std::uint32_t>::max();

namespace lazy_association_detail {

// Whether a comes before b: higher key; at equal keys a bound before an exact value; then the
// eager order (observation, slot).
inline bool before(const AssociationCandidate& a, const AssociationCandidate& b) {
  if (a.log_likelihood != b.log_likelihood) return a.log_likelihood > b.log_likelihood;
  const bool a_bound = a.tag == kBoundOnly;
  const bool b_bound = b.tag == kBoundOnly;
  if (a_bound != b_bound) return a_bound;
  if (a.observation != b.observation) return a.observation < b.observation;
  return a.slot < b.slot;
}

}  // namespace lazy_association_detail

// `log_unassociated(j)`: observation j's score of "no landmark"; `same_for_all`: it is one
// value (the scalar overload of associate_maximum_likelihood). Reorders and shrinks
// `candidates` (see above); writes assignment[j] for every j. Returns the log weight factor.
template <class Unassociated, class Evaluate>
double lazy_maximum_likelihood(std::vector<AssociationCandidate>& candidates,
                               const Unassociated& log_unassociated, bool same_for_all,
                               std::span<std::int64_t> assignment, Evaluate&& evaluate) {
  using lazy_association_detail::before;
  std::fill(assignment.begin(), assignment.end(), kNewLandmark);
  const auto heap_less = [](const AssociationCandidate& a, const AssociationCandidate& b) {
    return before(b, a);
  };
  const auto first = candidates.begin();
  std::make_heap(first, candidates.end(), heap_less);
  // [0, live): the heap; [live, size): popped, exact, or dropped (tag kBoundOnly).
  std::size_t live = candidates.size();
  double log_weight = 0.0;
  std::size_t assigned = 0;
  constexpr std::size_t kListed = 32;  // the taken slots, as in association.cc
  std::array<memory::Slot, kListed> taken_slots;
  const auto taken = [&](memory::Slot slot) {
    if (assigned <= kListed) {
      return std::find(taken_slots.begin(), taken_slots.begin() + assigned, slot) !=
             taken_slots.begin() + assigned;
    }
    return std::find(assignment.begin(), assignment.end(), static_cast<std::int64_t>(slot)) !=
           assignment.end();
  };
  while (live > 0 && assigned < assignment.size()) {
    std::pop_heap(first, first + static_cast<std::ptrdiff_t>(live), heap_less);
    --live;
    AssociationCandidate& cand = candidates[live];
    if (cand.tag == kBoundOnly) {
      if (assignment[cand.observation] != kNewLandmark) continue;  // cannot be taken: dropped
      if (!evaluate(cand)) {
        cand.tag = kBoundOnly;
        continue;
      }
      ++live;
      std::push_heap(first, first + static_cast<std::ptrdiff_t>(live), heap_less);
      continue;
    }
    if (cand.log_likelihood < log_unassociated(cand.observation)) {
      if (same_for_all) break;  // every later one is below too
      continue;
    }
    if (assignment[cand.observation] != kNewLandmark || taken(cand.slot)) continue;
    assignment[cand.observation] = cand.slot;
    log_weight += cand.log_likelihood;
    if (assigned < kListed) taken_slots[assigned] = cand.slot;
    ++assigned;
  }
  // What the heap still holds matters only for the observations left new: their candidates'
  // distances go into the report, so those are evaluated; the rest is dropped.
  for (std::size_t c = 0; c < live; ++c) {
    AssociationCandidate& cand = candidates[c];
    if (cand.tag != kBoundOnly || assignment[cand.observation] != kNewLandmark) continue;
    if (!evaluate(cand)) cand.tag = kBoundOnly;
  }
  std::erase_if(candidates, [](const AssociationCandidate& c) { return c.tag == kBoundOnly; });
  if (same_for_all) {
    log_weight += static_cast<double>(assignment.size() - assigned) * log_unassociated(0);
  } else {
    for (std::size_t j = 0; j < assignment.size(); ++j) {
      if (assignment[j] == kNewLandmark) log_weight += log_unassociated(j);
    }
  }
  return log_weight;
}

}  // namespace fastslam::engine::internal
